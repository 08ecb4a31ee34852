// Which predictor and entropy coder a ptm tile gets (docs/codecs.md, "ptm (6)"): the smallest
// predictor by estimate, the smallest encoding among predictors, and what each `effort`
// writes. The codec itself (codec_ptm.cpp, codec_ptm_decode.cpp, ptm_walk.h) codes whatever it
// is told.
#include <algorithm>
#include <cstdint>
#include <iterator>
#include <optional>
#include <span>
#include <utility>
#include <vector>

#include "ptm/ptm_codec.h"

namespace tessera::detail {

namespace {

// `effort` picks ptm's point on its size/decode-speed trade-off, measured on the codec study's
// three inputs (docs/codecs.md, "ptm (6)"; docs/benchmarks.md):
// - 1: nearest parent with zstd, the fastest to decode (about 240-254 MP/s per core);
// - 2: per tile the smaller of nearest parent with zstd and coder 7, the lane coder
//   (ptm_lanes.h), which decodes eight rows side by side, with the smaller of nearest parent
//   and the neighbour median; where the median won, least squares with the weights fitted
//   without predictor 4's estimate where its estimate is 2 % smaller, and with them where
//   those save 25 % again; then the parent-corrected predictor where its estimate is 25 %
//   below the choice so far; then, with 3 or 4 channels, the choice with green-led contexts
//   (ptm::lanes::leadByGreen) where they save 2 %. In the lanes nearest parent, the median
//   and least squares without the estimate decode at 150-185 MP/s per core on the codec
//   study's inputs, predictor 4 and least squares with the estimate at 100-115
//   (docs/benchmarks.md, "thirteenth session"); green-led contexts cost 0-8 % ("fourteenth
//   session");
// - 3 and the default: predictors 1, 3 and 4 entropy-coded by rANS. Of its coders, fastest to
//   decode first: 7 (the lanes, coder 1's contexts), 1 (per-channel contexts,
//   model family 1), 2 (chained contexts), 3 (model family 2), 4 (both), 6 (4 with the
//   parent's gradients and the neighbours' errors in the activity), each tile takes the
//   fastest whose estimated size is within 3 % of coder 6's.
//   Coder 5 (4 with the neighbours' gradients and errors) is left out: coder 6 coded the
//   study's photograph 2.8 % smaller and its other inputs within 0.4 %, 0-8 % slower to
//   decode. Smaller than effort 1 but a fifth to a ninth of its decode speed.
// - the default and 4 and above: as 3, and where the neighbour median is the best of the
//   three, predictor 5 (least squares) if coder 6 codes it at least 3 % smaller, with the
//   weights fitted without predictor 4's estimate where coder 6 codes those no larger (the
//   decoders then skip predictor 4's work). The codec study's photograph came out 20 %
//   smaller than at effort 3, at about half its decode and a third of its encode speed; its
//   map and synthetic source came out the same.
//   Bytes are what ptm is for (storage, and remote refinement over a link), so the smallest is
//   the default.
constexpr size_t kSlowerCoderMinSavingPercent = 3;
// Effort 2: predictor 5 without predictor 4's estimate decodes at 85-105 % of the median's
// speed in the lanes, so it takes a tile where it saves this much over the median.
constexpr size_t kLanesLeastSquaresMinSavingPercent = 2;
// Effort 2: predictor 4, and predictor 5 with predictor 4's estimate, decode at 60-75 % of the
// speed of the others in the lanes (docs/benchmarks.md, "thirteenth session"), so they take
// a tile only where they save about as much over the choice so far: on the study's map, 10 %
// left a quarter of its bytes to predictor 4 and decoded at 145-154 MP/s per core, 25 % none,
// at 155-178, 3 % larger.
constexpr size_t kLanesSlowerPredictorMinSavingPercent = 25;
// Effort 2: the lanes' green-led contexts (ptm::lanes::leadByGreen) cost the SIMD decoder a
// comparison and a blend on each step's longest chain of instructions. On the codec study's
// photograph they save about 10 % in nearly every tile; with 0 % instead of 2 % the map came
// out 0.6 % smaller and decoded at 145-151 MP/s per core against 150-162, in turn three times
// (docs/benchmarks.md, "fourteenth session").
constexpr size_t kLanesGreenLedMinSavingPercent = 2;
// Fastest to decode first (docs/codecs.md, "ptm (6)").
constexpr PtmCoder kRansCodersByDecodeSpeed[] = {
    PtmCoder::kRansLanes,          PtmCoder::kRans,
    PtmCoder::kRansChained,        PtmCoder::kRansMixture,
    PtmCoder::kRansMixtureChained, PtmCoder::kRansParentErrors};
constexpr Predictor kSmallestPtmPredictors[] = {
    Predictor::kParentNearest, Predictor::kNeighbourMedian, Predictor::kParentCorrected};
// Predictor 5 decodes at about half the others' speed (its fitted sum of nine terms on top of
// predictor 4's estimate), so the default takes it only where it saves this much.
constexpr size_t kLeastSquaresMinSavingPercent = 3;
// The effort that applies the default's rule without predictor 5: on images where predictor 5
// wins, a third of the encoding time and twice the decode speed, for larger tiles.
constexpr int kEffortWithoutLeastSquares = 3;
// Predictor 5 refines the neighbour median with the parent, and on the codec study's inputs it
// beat the best of the others by 3 % only in tiles where the median was that best: trying it
// there alone gave the same bytes on all three inputs and kept the map's and the synthetic
// source's encoding at the speed of effort 3 instead of half of it.

}  // namespace

Result<Predictor> smallestPtmPredictor(const ImageView& tile, const EncodeOptions& options,
                                       const ParentTexels* parent,
                                       std::span<const Predictor> predictors, PtmCoder coder,
                                       CodecScratch* scratch, size_t* estimated_bytes) {
  if (parent == nullptr || predictors.empty()) {
    if (estimated_bytes != nullptr) {
      TESSERA_ASSIGN_OR_RETURN(
          *estimated_bytes,
          estimatePtmBytes(tile, options, nullptr, Predictor::kRoot, coder, scratch));
    }
    return Predictor::kRoot;
  }
  Predictor best = predictors[0];
  size_t best_bytes = SIZE_MAX;
  for (Predictor predictor : predictors) {
    TESSERA_ASSIGN_OR_RETURN(size_t bytes,
                             estimatePtmBytes(tile, options, parent, predictor, coder, scratch));
    if (bytes < best_bytes) {
      best = predictor;
      best_bytes = bytes;
    }
  }
  if (estimated_bytes != nullptr) *estimated_bytes = best_bytes;
  return best;
}

Result<std::vector<uint8_t>> encodePtmSmallest(const ImageView& tile, const EncodeOptions& options,
                                               const ParentTexels* parent,
                                               std::span<const Predictor> predictors,
                                               PtmCoder coder, CodecScratch* scratch) {
  if (parent == nullptr || predictors.empty())
    return encodePtm(tile, options, nullptr, Predictor::kRoot, coder, scratch);
  if (coder == PtmCoder::kZstd) {
    std::optional<std::vector<uint8_t>> smallest;
    for (Predictor predictor : predictors) {
      TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> payload,
                               encodePtm(tile, options, parent, predictor, coder, scratch));
      if (!smallest || payload.size() < smallest->size()) smallest = std::move(payload);
    }
    return std::move(*smallest);
  }
  // rANS: chosen by estimate, then coded once.
  TESSERA_ASSIGN_OR_RETURN(Predictor best, smallestPtmPredictor(tile, options, parent, predictors,
                                                                coder, scratch, nullptr));
  return encodePtm(tile, options, parent, best, coder, scratch);
}

Result<std::vector<uint8_t>> encodePtmForEffort(const ImageView& tile, const EncodeOptions& options,
                                                const ParentTexels* parent, CodecScratch* scratch) {
  // The effort selects the mode, so zstd's streams keep their measured level.
  EncodeOptions stream_options = options;
  stream_options.effort = 0;
  switch (options.effort) {
    case 1:
      return encodePtm(tile, stream_options, parent, Predictor::kParentNearest, PtmCoder::kZstd,
                       scratch);
    case 2: {
      TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> nearest,
                               encodePtm(tile, stream_options, parent, Predictor::kParentNearest,
                                         PtmCoder::kZstd, scratch));
      // The lanes' predictor by estimate, the payload coded once from its recording: the
      // smaller of the median and nearest parent, which decode fastest, unless predictor 4, or
      // where it is not, predictor 5 without predictor 4's estimate saves enough, and then
      // with the estimate where that saves enough again.
      PtmRecording chosen, candidate;
      std::vector<uint8_t> chosen_models, candidate_models;
      TESSERA_TRY(recordPtm(tile, parent, Predictor::kNeighbourMedian, PtmCoder::kRansLanes,
                            scratch, nullptr, chosen));
      size_t chosen_bytes = estimateRecordedPtm(chosen, PtmCoder::kRansLanes, &chosen_models);
      auto takeIfItSaves = [&](size_t percent) {
        const size_t bytes =
            estimateRecordedPtm(candidate, PtmCoder::kRansLanes, &candidate_models);
        if (bytes * 100 > chosen_bytes * (100 - percent)) return false;
        std::swap(chosen, candidate);
        std::swap(chosen_models, candidate_models);
        chosen_bytes = bytes;
        return true;
      };
      if (parent != nullptr) {
        TESSERA_TRY(recordPtm(tile, parent, Predictor::kParentNearest, PtmCoder::kRansLanes,
                              scratch, nullptr, candidate));
        const size_t nearest_bytes =
            estimateRecordedPtm(candidate, PtmCoder::kRansLanes, &candidate_models);
        if (nearest_bytes < chosen_bytes) {
          std::swap(chosen, candidate);
          std::swap(chosen_models, candidate_models);
          chosen_bytes = nearest_bytes;
        }
        // Predictor 5's fit costs a walk of its own: only where the median's lanes won, as the
        // default tries it only where the median won. One fit gives both weight sets.
        if (Predictor(chosen.header[0]) == Predictor::kNeighbourMedian &&
            chosen_bytes < nearest.size()) {
          PtmLeastSquaresFit fit;
          fit.without_estimate = true;
          TESSERA_TRY(recordPtm(tile, parent, Predictor::kLeastSquares, PtmCoder::kRansLanes,
                                scratch, &fit, candidate));
          if (takeIfItSaves(kLanesLeastSquaresMinSavingPercent)) {
            fit.without_estimate = false;
            TESSERA_TRY(recordPtm(tile, parent, Predictor::kLeastSquares, PtmCoder::kRansLanes,
                                  scratch, &fit, candidate));
            takeIfItSaves(kLanesSlowerPredictorMinSavingPercent);
          }
        }
        TESSERA_TRY(recordPtm(tile, parent, Predictor::kParentCorrected, PtmCoder::kRansLanes,
                              scratch, nullptr, candidate));
        takeIfItSaves(kLanesSlowerPredictorMinSavingPercent);
      }
      // Green-led contexts where they save enough for their cost in decode speed.
      if (tile.channels >= 3) {
        leadRecordingByGreen(chosen, candidate);
        takeIfItSaves(kLanesGreenLedMinSavingPercent);
      }
      std::vector<uint8_t> lanes =
          encodeRecordedPtm(chosen, PtmCoder::kRansLanes, scratch, &chosen_models);
      return lanes.size() < nearest.size() ? std::move(lanes) : std::move(nearest);
    }
    default: {
      // The predictor that suits the most elaborate coder (the smallest, as a rule), then the
      // fastest coder within 3 % of it: estimated fastest first, so a tile that a fast coder
      // codes well costs one estimate more, not four. Each walk is recorded once and serves
      // every estimate of a coder that walks alike, and the payload that follows.
      constexpr size_t kSlowest = std::size(kRansCodersByDecodeSpeed) - 1;
      constexpr PtmCoder kReference = kRansCodersByDecodeSpeed[kSlowest];
      constexpr Predictor kWithoutParent[] = {Predictor::kRoot};
      const std::span<const Predictor> predictors =
          parent != nullptr ? std::span<const Predictor>(kSmallestPtmPredictors) : kWithoutParent;
      // Each kept recording with the model bytes its estimate chose, which its payload reuses.
      PtmRecording reference, candidate;
      std::vector<uint8_t> reference_models, candidate_models;
      Predictor predictor = predictors[0];
      size_t slowest_bytes = SIZE_MAX;
      for (Predictor tried : predictors) {
        TESSERA_TRY(recordPtm(tile, parent, tried, kReference, scratch, nullptr, candidate));
        const size_t bytes = estimateRecordedPtm(candidate, kReference, &candidate_models);
        if (bytes < slowest_bytes) {
          std::swap(reference, candidate);
          std::swap(reference_models, candidate_models);
          predictor = tried;
          slowest_bytes = bytes;
        }
      }
      // Predictor 5 where it saves at least kLeastSquaresMinSavingPercent, tried only where
      // the neighbour median won (kLeastSquaresOnlyAfterTheMedian); its weights are fitted once
      // for every walk that follows.
      PtmLeastSquaresFit fit;
      if (options.effort != kEffortWithoutLeastSquares &&
          predictor == Predictor::kNeighbourMedian) {
        TESSERA_TRY(recordPtm(tile, parent, Predictor::kLeastSquares, kReference, scratch, &fit,
                              candidate));
        const size_t fitted_bytes = estimateRecordedPtm(candidate, kReference, &candidate_models);
        if (fitted_bytes * 100 <= slowest_bytes * (100 - kLeastSquaresMinSavingPercent)) {
          std::swap(reference, candidate);
          std::swap(reference_models, candidate_models);
          predictor = Predictor::kLeastSquares;
          slowest_bytes = fitted_bytes;
          // The weights without predictor 4's estimate where they code no larger: the decoders
          // then skip predictor 4's work.
          fit.without_estimate = true;
          TESSERA_TRY(recordPtm(tile, parent, Predictor::kLeastSquares, kReference, scratch, &fit,
                                candidate));
          const size_t plain_bytes = estimateRecordedPtm(candidate, kReference, &candidate_models);
          if (plain_bytes <= slowest_bytes) {
            std::swap(reference, candidate);
            std::swap(reference_models, candidate_models);
            slowest_bytes = plain_bytes;
          } else {
            fit.without_estimate = false;
          }
        }
      }
      std::vector<PtmRecording> walks;  // of the faster coders, one per kind of walk
      for (size_t chosen = 0; chosen < kSlowest; ++chosen) {
        const PtmCoder coder = kRansCodersByDecodeSpeed[chosen];
        if (!codesPredictor(coder, predictor)) continue;
        auto walk = std::find_if(walks.begin(), walks.end(), [&](const PtmRecording& recorded) {
          return walksAlike(recorded.coder, coder);
        });
        if (walk == walks.end()) {
          walk = walks.emplace(walks.end());
          TESSERA_TRY(recordPtm(tile, parent, predictor, coder, scratch, &fit, *walk));
        }
        if (estimateRecordedPtm(*walk, coder, &candidate_models) * 100 <=
            slowest_bytes * (100 + kSlowerCoderMinSavingPercent))
          return encodeRecordedPtm(*walk, coder, scratch, &candidate_models);
      }
      return encodeRecordedPtm(reference, kReference, scratch, &reference_models);
    }
  }
}

}  // namespace tessera::detail
