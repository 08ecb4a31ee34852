// ptm's encoder (docs/codecs.md, "ptm (6)"): the texel walk (ptm_walk.h) records what a tile's
// decoded parent does not already say, and zstd or rANS codes it. Which predictor and coder a
// tile gets is codec_ptm_choice.cpp's; the decoder is codec_ptm_decode.cpp.
#include <cstring>
#include <memory>

#include <tessera/check.h>

#include "ptm/ptm_codec.h"
#include "format/byte_io.h"
#include "ptm/ptm_lanes.h"
#include "ptm/ptm_least_squares.h"
#include "ptm/ptm_rans.h"
#include "ptm/ptm_walk.h"

namespace tessera::detail {

using namespace ptm;

namespace {

// Levels 1-9 gave sizes within 1 % of each other on residual planes (Huffman-coded literals
// with few matches), so the cheapest level wins: the builder encodes every tile.
constexpr int kDefaultZstdLevel = 1;

// What a table must save beyond its bytes: the lanes' SIMD decoder pays for each in time.
double tableMinGainBytes(PtmCoder coder) {
  return coder == PtmCoder::kRansLanes ? lanes::kTableMinGainBytes : 0;
}

// The model bytes of `coder` for the recorded symbols, and the bits the symbols cost under
// them: coder 7 shares models among its contexts where that costs little
// (lanes::kShareModelsSlack).
double chooseCoderModels(PtmCoder coder, const PtmRecording& recording,
                         std::vector<uint8_t>& params) {
  const double bits = rans::chooseModels(familyOf(coder), recording.counts, params);
  if (coder != PtmCoder::kRansLanes) return bits;
  return rans::shareModels(familyOf(coder), recording.counts, lanes::kShareModelsSlack, params);
}

// Fits predictor 5's weights to the tile `walk` covers into `weights`, and without predictor
// 4's estimate into `without_estimate`. `walk` has no weights yet (prepareWalk's null): the fit
// uses the texels, not the predictions.
void fitLeastSquares(const Walk& walk, uint32_t channels, int8_t* weights,
                     int8_t* without_estimate) {
  auto fit = std::make_unique<LsFit>();
  static const int8_t kNoWeights[lsWeightBytes(4)] = {};
  Walk fitting = walk;
  fitting.ls_weights = kNoWeights;
  fitting.ls_fit = fit.get();
  fitting.errors = nullptr;
  DiscardingCoder discard;
  code<true>(Predictor::kLeastSquares, channels, fitting, discard);
  solveLeastSquares(*fit, channels, true, weights);
  solveLeastSquares(*fit, channels, false, without_estimate);
}

// encodePtm, or with `estimated_bytes` and a rANS coder only the payload's size to within a
// few bytes: the texel walk and the model choice, without the rANS pass (a quarter of a
// tile's encoding time), for choosing between predictors and coders.
// With `recording` (a rANS coder only), only the walk: its symbols, contexts and header go
// there, for estimateRecordedPtm and encodeRecordedPtm.
Result<std::vector<uint8_t>> encodePtmOrEstimate(const ImageView& tile,
                                                 const EncodeOptions& options,
                                                 const ParentTexels* parent, Predictor predictor,
                                                 PtmCoder coder, CodecScratch* scratch,
                                                 PtmLeastSquaresFit* fit, size_t* estimated_bytes,
                                                 PtmRecording* recording = nullptr) {
  ScratchRef ref(scratch);
  PtmState* state = ptmState(ref, CodecSide::kEncode);
  const uint32_t width = tile.width_px, height = tile.height_px, channels = tile.channels;
  if (parent == nullptr) predictor = Predictor::kRoot;
  const bool has_parent = predictor != Predictor::kRoot;
  if (!codesPredictor(coder, predictor))
    return fail(ErrorCode::kInvalidArgument,
                "ptm: coder 7 (lanes) codes every predictor but 2 (bilinear parent)");
  std::span<const uint8_t> packed = packedTexels(tile, state->texels);
  int8_t ls_weights[lsWeightBytes(4)] = {};
  const bool least_squares = predictor == Predictor::kLeastSquares;
  const bool fits = least_squares && (fit == nullptr || !fit->fitted);
  const bool without_estimate = fit != nullptr && fit->without_estimate;
  if (least_squares && !fits) {
    static_assert(sizeof fit->weights == sizeof ls_weights &&
                  sizeof fit->weights_without_estimate == sizeof ls_weights);
    std::memcpy(ls_weights, without_estimate ? fit->weights_without_estimate : fit->weights,
                sizeof ls_weights);
  }
  AxisMap columns, rows;
  // Encoding only reads the texels; the shared routine takes a mutable pointer for decoding.
  TESSERA_ASSIGN_OR_RETURN(
      Walk walk, prepareWalk(const_cast<uint8_t*>(packed.data()), width, height, channels, parent,
                             predictor, coder, fits ? nullptr : ls_weights, *state, columns, rows));
  std::vector<uint8_t> payload = {uint8_t(predictor), uint8_t(coder)};
  if (least_squares) {
    if (fits) {
      int8_t weights[lsWeightBytes(4)] = {}, weights_without_estimate[lsWeightBytes(4)] = {};
      fitLeastSquares(walk, channels, weights, weights_without_estimate);
      std::memcpy(ls_weights, without_estimate ? weights_without_estimate : weights,
                  sizeof ls_weights);
      if (fit != nullptr) {
        std::memcpy(fit->weights, weights, sizeof weights);
        std::memcpy(fit->weights_without_estimate, weights_without_estimate,
                    sizeof weights_without_estimate);
        fit->fitted = true;
      }
    }
    walk.ls_weights = ls_weights;
    for (size_t i = 0; i < lsWeightBytes(channels); ++i) payload.push_back(uint8_t(ls_weights[i]));
  }

  if (isRansCoder(coder)) {
    PtmRecording local;
    PtmRecording& out = recording != nullptr ? *recording : local;
    out.coder = coder;
    out.channels = channels;
    out.width = width;
    out.height = height;
    out.contexts = has_parent ? kParentContexts : kRootContexts;
    out.header = std::move(payload);
    const size_t symbols = size_t(width) * height * channels;
    out.symbols.resize(symbols);
    out.symbol_contexts.resize(symbols);
    uint8_t* const symbols_at = out.symbols.data();
    uint8_t* const contexts_at = out.symbol_contexts.data();
    if (isParentActivityCoder(coder)) {
      RansRecorder<true, true, true> recorder{symbols_at, contexts_at};
      code<true>(predictor, channels, walk, recorder);
    } else if (isErrorActivityCoder(coder)) {
      RansRecorder<true, true> recorder{symbols_at, contexts_at};
      code<true>(predictor, channels, walk, recorder);
    } else if (isChainedCoder(coder)) {
      RansRecorder<true, false> recorder{symbols_at, contexts_at};
      code<true>(predictor, channels, walk, recorder);
    } else {
      RansRecorder<false, false> recorder{symbols_at, contexts_at};
      code<true>(predictor, channels, walk, recorder);
    }
    out.counts = rans::countByContext(out.symbols, out.symbol_contexts, channels, out.contexts);
    if (recording != nullptr) return std::vector<uint8_t>{};
    if (estimated_bytes != nullptr) {
      *estimated_bytes = estimateRecordedPtm(out, coder);
      return std::vector<uint8_t>{};
    }
    return encodeRecordedPtm(out, coder, scratch);
  }

  const SymbolCounts counts =
      countSymbols(width, height, has_parent ? &columns : nullptr, has_parent ? &rows : nullptr);
  PlaneCoder<true> planes = planesIn<true>(state->plane, channels, counts);
  const PlaneCoder<true> starts = planes;
  code<true>(predictor, channels, walk, planes);
  const int level = options.effort != 0 ? options.effort : kDefaultZstdLevel;
  auto addStream = [&](const uint8_t* symbols, size_t count) -> Result<void> {
    if (count == 0) {
      appendU32(payload, 0);
      return {};
    }
    TESSERA_ASSIGN_OR_RETURN(
        std::vector<uint8_t> frame,
        compressZstdFrame({symbols, count}, level, "ptm payload", state->zstd_encoder));
    appendU32(payload, uint32_t(frame.size()));
    payload.insert(payload.end(), frame.begin(), frame.end());
    return {};
  };
  // The frames go to the zstd encoder's own buffer, so the planes stay valid throughout.
  for (uint32_t c = 0; c < channels; ++c) TESSERA_TRY(addStream(starts.residuals[c], counts.coded));
  if (has_parent)
    for (uint32_t c = 0; c < channels; ++c)
      TESSERA_TRY(addStream(starts.remainders[c], counts.derived));
  if (estimated_bytes != nullptr) *estimated_bytes = payload.size();
  return payload;
}

}  // namespace

Result<std::vector<uint8_t>> encodePtm(const ImageView& tile, const EncodeOptions& options,
                                       const ParentTexels* parent, Predictor predictor,
                                       PtmCoder coder, CodecScratch* scratch,
                                       PtmLeastSquaresFit* fit) {
  return encodePtmOrEstimate(tile, options, parent, predictor, coder, scratch, fit, nullptr);
}

Result<void> recordPtm(const ImageView& tile, const ParentTexels* parent, Predictor predictor,
                       PtmCoder coder, CodecScratch* scratch, PtmLeastSquaresFit* fit,
                       PtmRecording& recording) {
  if (!isRansCoder(coder))
    return fail(ErrorCode::kInvalidArgument, "ptm: only the rANS coders' walks are recorded");
  TESSERA_TRY(
      encodePtmOrEstimate(tile, {}, parent, predictor, coder, scratch, fit, nullptr, &recording));
  return {};
}

void leadRecordingByGreen(const PtmRecording& recording, PtmRecording& led) {
  TESSERA_CHECK(walksAlike(recording.coder, PtmCoder::kRansLanes) && recording.channels >= 3)
      << "ptm: green leads coder 7's red and blue only";
  led = recording;
  if (led.green_led) return;
  lanes::leadByGreen(led.symbols, led.symbol_contexts, led.channels);
  led.counts = rans::countByContext(led.symbols, led.symbol_contexts, led.channels, led.contexts);
  led.green_led = true;
}

size_t estimateRecordedPtm(const PtmRecording& recording, PtmCoder coder,
                           std::vector<uint8_t>* models) {
  // Another walk's symbols under this coder's contexts would estimate nothing meaningful.
  TESSERA_CHECK(walksAlike(recording.coder, coder)) << "ptm: a recording of another walk";
  std::vector<uint8_t> chosen;
  std::vector<uint8_t>& params = models != nullptr ? *models : chosen;
  chooseCoderModels(coder, recording, params);
  rans::Tables tables;
  rans::chooseTables(familyOf(coder), recording.counts, params, tables, tableMinGainBytes(coder));
  // The states: the lanes' header holds them with the streams' lengths.
  const size_t states = coder == PtmCoder::kRansLanes ? lanes::headerBytes(recording.channels)
                                                      : 4 * recording.channels;
  return recording.header.size() + params.size() + tables.section.size() + size_t(tables.bits / 8) +
         states;
}

std::vector<uint8_t> encodeRecordedPtm(const PtmRecording& recording, PtmCoder coder,
                                       CodecScratch* scratch, const std::vector<uint8_t>* models,
                                       std::optional<double> table_min_gain_bytes) {
  // Coded under another walk's contexts, the payload would not decode to the tile.
  TESSERA_CHECK(walksAlike(recording.coder, coder)) << "ptm: a recording of another walk";
  ScratchRef ref(scratch);
  PtmState* state = ptmState(ref, CodecSide::kEncode);
  std::vector<uint8_t> chosen;
  if (models == nullptr) {
    chooseCoderModels(coder, recording, chosen);
    models = &chosen;
  }
  rans::Tables tables;
  const bool with_tables =
      rans::chooseTables(familyOf(coder), recording.counts, *models, tables,
                         table_min_gain_bytes.value_or(tableMinGainBytes(coder)));
  std::vector<uint8_t> payload = recording.header;
  payload[1] = uint8_t(uint8_t(coder) | (with_tables ? kPtmTablesFlag : 0) |
                       (recording.green_led ? kPtmGreenLedFlag : 0));
  payload.insert(payload.end(), models->begin(), models->end());
  payload.insert(payload.end(), tables.section.begin(), tables.section.end());
  if (coder == PtmCoder::kRansLanes) {
    TESSERA_CHECK(codesPredictor(coder, Predictor(recording.header[0])))
        << "ptm: coder 7 (lanes) codes every predictor but 2 (bilinear parent)";
    lanes::encode(recording.symbols, recording.symbol_contexts, recording.width, recording.height,
                  recording.channels, recording.contexts, tables.context_models, payload);
    return payload;
  }
  rans::encode(familyOf(coder), recording.symbols, recording.symbol_contexts, recording.channels,
               recording.contexts, tables.context_models, state->compressed, payload);
  return payload;
}

Result<size_t> estimatePtmBytes(const ImageView& tile, const EncodeOptions& options,
                                const ParentTexels* parent, Predictor predictor, PtmCoder coder,
                                CodecScratch* scratch, PtmLeastSquaresFit* fit) {
  size_t bytes = 0;
  TESSERA_TRY(encodePtmOrEstimate(tile, options, parent, predictor, coder, scratch, fit, &bytes));
  return bytes;
}

}  // namespace tessera::detail
