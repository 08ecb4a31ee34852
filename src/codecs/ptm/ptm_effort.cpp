// What each ptm `effort` writes (docs/codecs.md, "ptm (6)", "Efforts"), measured on the codec
// study's three inputs (bench/pyramid_study.cpp): 1 the fastest to decode, 2 the lanes, whose
// SIMD decoder is five times as fast as the walk's, and 0 (the default) and 3 and above the
// smallest. The codec itself (ptm_encode.cpp) codes whatever it is told.
#include <algorithm>
#include <cstdint>
#include <iterator>
#include <utility>
#include <vector>

#include "ptm/ptm_encode.h"

namespace tessera::detail {

namespace {

// Effort 2 takes predictor 5 without predictor 4's estimate, which decodes at 85-105 % of the
// median's speed in the lanes, where it saves this much over the median.
constexpr size_t kLanesLeastSquaresMinSavingPercent = 2;
// Effort 2 takes predictor 4, which decodes at 60-75 % of the others' speed in the lanes, only
// where it saves about as much.
constexpr size_t kLanesParentCorrectedMinSavingPercent = 25;
// Green-led contexts cost the SIMD decoder a compare and a blend on its longest chain.
constexpr size_t kLanesGreenLedMinSavingPercent = 2;
// The default: the coder fastest to decode whose estimate is within this much of coder 6's.
constexpr size_t kSlowerCoderMinSavingPercent = 3;
constexpr PtmCoder kRansCodersByDecodeSpeed[] = {PtmCoder::kRansLanes, PtmCoder::kRans,
                                                 PtmCoder::kRansChained, PtmCoder::kRansMixture,
                                                 PtmCoder::kRansMixtureChained};
constexpr PtmCoder kReference = PtmCoder::kRansParentErrors;
constexpr Predictor kDefaultPredictors[] = {Predictor::kParentNearest, Predictor::kNeighbourMedian,
                                            Predictor::kParentCorrected};
// Predictor 5 decodes at about half the others' speed: the default takes it where it saves
// this much. It refines the median with the parent, and on the study's inputs it saved that
// much only in tiles where the median was the best of the others, so it is tried there alone.
constexpr size_t kLeastSquaresMinSavingPercent = 3;

// A walk recorded with the model bytes its estimate chose, which its payload reuses.
struct Candidate {
  PtmRecording recording;
  std::vector<uint8_t> models;
  size_t bytes = SIZE_MAX;
  void estimate(PtmCoder coder) { bytes = estimateRecordedPtm(recording, coder, &models); }
};
// Swaps `candidate` into `chosen` where its estimate is smaller.
bool takeIfSmaller(Candidate& candidate, Candidate& chosen) {
  if (candidate.bytes >= chosen.bytes) return false;
  std::swap(chosen, candidate);
  return true;
}
// Swaps `candidate` into `chosen` where its estimate is at least `percent` % smaller.
bool takeIfItSaves(Candidate& candidate, Candidate& chosen, size_t percent) {
  if (candidate.bytes * 100 > chosen.bytes * (100 - percent)) return false;
  std::swap(chosen, candidate);
  return true;
}

// Effort 2: per tile the smaller of nearest parent with zstd and coder 7 with the smaller of
// the median and nearest parent by estimate; where the median won and beat zstd, predictor 5
// without predictor 4's estimate if it saves 2 %; predictor 4 if it saves 25 %; then green-led
// contexts if they save 2 %.
Result<std::vector<uint8_t>> encodeLanes(const ImageView& tile, const ParentTexels* parent,
                                         CodecScratch* scratch) {
  constexpr PtmCoder kLanes = PtmCoder::kRansLanes;
  TESSERA_ASSIGN_OR_RETURN(
      std::vector<uint8_t> nearest,
      encodePtm(tile, {}, parent, Predictor::kParentNearest, PtmCoder::kZstd, scratch));
  Candidate chosen, candidate;
  auto record = [&](Predictor predictor, PtmLeastSquaresFit* fit = nullptr) -> Result<void> {
    TESSERA_TRY(recordPtm(tile, parent, predictor, kLanes, scratch, fit, candidate.recording));
    candidate.estimate(kLanes);
    return {};
  };
  TESSERA_TRY(record(Predictor::kNeighbourMedian));
  takeIfSmaller(candidate, chosen);
  if (parent != nullptr) {
    TESSERA_TRY(record(Predictor::kParentNearest));
    takeIfSmaller(candidate, chosen);
    if (Predictor(chosen.recording.header[0]) == Predictor::kNeighbourMedian &&
        chosen.bytes < nearest.size()) {
      PtmLeastSquaresFit fit;
      fit.without_estimate = true;
      TESSERA_TRY(record(Predictor::kLeastSquares, &fit));
      takeIfItSaves(candidate, chosen, kLanesLeastSquaresMinSavingPercent);
    }
    TESSERA_TRY(record(Predictor::kParentCorrected));
    takeIfItSaves(candidate, chosen, kLanesParentCorrectedMinSavingPercent);
  }
  if (tile.channels >= 3) {
    leadRecordingByGreen(chosen.recording, candidate.recording);
    candidate.estimate(kLanes);
    takeIfItSaves(candidate, chosen, kLanesGreenLedMinSavingPercent);
  }
  std::vector<uint8_t> lanes = encodeRecordedPtm(chosen.recording, kLanes, scratch, &chosen.models);
  return lanes.size() < nearest.size() ? std::move(lanes) : std::move(nearest);
}

// The default: the predictor whose coder-6 estimate is smallest (of 1, 3 and 4; where 3 wins,
// predictor 5 if it saves 3 %, with the weights without predictor 4's estimate where they code
// no larger), then the coder fastest to decode within 3 % of coder 6's estimate, else coder 6.
// Each walk is recorded once for every estimate of the coders that walk alike, and the payload.
Result<std::vector<uint8_t>> encodeSmallest(const ImageView& tile, const ParentTexels* parent,
                                            CodecScratch* scratch) {
  constexpr Predictor kWithoutParent[] = {Predictor::kRoot};
  const std::span<const Predictor> predictors =
      parent != nullptr ? std::span<const Predictor>(kDefaultPredictors) : kWithoutParent;
  Candidate reference, candidate;
  for (Predictor tried : predictors) {
    TESSERA_TRY(recordPtm(tile, parent, tried, kReference, scratch, nullptr, candidate.recording));
    candidate.estimate(kReference);
    takeIfSmaller(candidate, reference);
  }
  PtmLeastSquaresFit fit;
  Predictor predictor = Predictor(reference.recording.header[0]);
  if (predictor == Predictor::kNeighbourMedian) {
    TESSERA_TRY(recordPtm(tile, parent, Predictor::kLeastSquares, kReference, scratch, &fit,
                          candidate.recording));
    candidate.estimate(kReference);
    if (takeIfItSaves(candidate, reference, kLeastSquaresMinSavingPercent)) {
      predictor = Predictor::kLeastSquares;
      fit.without_estimate = true;
      TESSERA_TRY(
          recordPtm(tile, parent, predictor, kReference, scratch, &fit, candidate.recording));
      candidate.estimate(kReference);
      if (!takeIfItSaves(candidate, reference, 0)) fit.without_estimate = false;
    }
  }
  std::vector<PtmRecording> walks;  // one per kind of walk of the faster coders
  std::vector<uint8_t> models;
  for (PtmCoder coder : kRansCodersByDecodeSpeed) {
    // Coder 7 has no predictor 5 with predictor 4's estimate.
    if (coder == PtmCoder::kRansLanes && predictor == Predictor::kLeastSquares &&
        !fit.without_estimate)
      continue;
    auto walk = std::find_if(walks.begin(), walks.end(), [&](const PtmRecording& recorded) {
      return walksAlike(recorded.coder, coder);
    });
    if (walk == walks.end()) {
      walk = walks.emplace(walks.end());
      TESSERA_TRY(recordPtm(tile, parent, predictor, coder, scratch, &fit, *walk));
    }
    if (estimateRecordedPtm(*walk, coder, &models) * 100 <=
        reference.bytes * (100 + kSlowerCoderMinSavingPercent))
      return encodeRecordedPtm(*walk, coder, scratch, &models);
  }
  return encodeRecordedPtm(reference.recording, kReference, scratch, &reference.models);
}

}  // namespace

Result<std::vector<uint8_t>> encodePtmForEffort(const ImageView& tile, const EncodeOptions& options,
                                                const ParentTexels* parent, CodecScratch* scratch) {
  // The effort picks the mode; zstd's streams keep their level.
  if (options.effort == 1)
    return encodePtm(tile, {}, parent, Predictor::kParentNearest, PtmCoder::kZstd, scratch);
  if (options.effort == 2) return encodeLanes(tile, parent, scratch);
  return encodeSmallest(tile, parent, scratch);
}

}  // namespace tessera::detail
