// ptm's encoder (ptm_encode.h): the texel walk (ptm_walk.h) records what the tile's decoded
// parent does not already say, and zstd or rANS codes it.
#include "ptm/ptm_encode.h"

#include <cstring>
#include <memory>

#include <tessera/check.h>

#include "format/byte_io.h"
#include "ptm/ptm_lanes.h"
#include "ptm/ptm_least_squares_fit.h"
#include "ptm/ptm_walk.h"

namespace tessera::detail {

using namespace ptm;

namespace {

// zstd levels 1-9 coded residual planes within 1 % of each other: the cheapest wins.
constexpr int kDefaultZstdLevel = 1;

// The walk's side that gathers predictor 5's normal equations and codes nothing.
struct LsFitter : WalkSide {
  static constexpr bool kFits = true;
  LsFit* normal;
  void residual(uint32_t /*channel*/, uint32_t /*context*/, uint8_t& /*symbol*/) {}
  void remainder(uint32_t /*channel*/, uint32_t /*context*/, uint8_t& /*symbol*/) {}
  void fit(uint32_t set, uint32_t c, const LsTexels& texels, int estimate16, int median,
           int value) {
    int terms[kLsTerms];
    leastSquaresTerms(texels, estimate16, median, terms);
    normal->add(set, c, terms, 16 * (value - median));
  }
};

// The walk of `tile` with `predictor` (predictor 0 without a parent), and the payload's header
// in `header`: the predictor, the coder and predictor 5's weights, which the walk reads there.
// Weights not yet in `fit` are fitted first, from a walk that needs the texels only.
Result<Walk> prepareEncode(const ImageView& tile, const ParentTexels* parent, Predictor predictor,
                           PtmCoder coder, PtmState& state, PtmLeastSquaresFit* fit,
                           AxisMap& columns, AxisMap& rows, std::vector<uint8_t>& header) {
  if (parent == nullptr) predictor = Predictor::kRoot;
  const uint32_t channels = tile.channels;
  const bool least_squares = predictor == Predictor::kLeastSquares;
  const bool fits = least_squares && (fit == nullptr || !fit->fitted);
  // Coder 7 has predictor 5 without predictor 4's estimate only.
  const bool without_estimate =
      coder == PtmCoder::kRansLanes || (fit != nullptr && fit->without_estimate);
  int8_t weights[lsWeightBytes(4)] = {};
  if (least_squares && !fits)
    std::memcpy(weights, without_estimate ? fit->weights_without_estimate : fit->weights,
                sizeof weights);
  // Encoding only reads the texels; the walk takes a mutable pointer for decoding.
  std::span<const uint8_t> packed = packedTexels(tile, state.texels);
  TESSERA_ASSIGN_OR_RETURN(
      Walk walk,
      prepareWalk(const_cast<uint8_t*>(packed.data()), tile.width_px, tile.height_px, channels,
                  parent, predictor, coder, fits ? nullptr : weights, state, columns, rows));
  header = {uint8_t(predictor), uint8_t(coder)};
  if (!least_squares) return walk;
  if (fits) {
    auto normal = std::make_unique<LsFit>();
    static const int8_t kNoWeights[lsWeightBytes(4)] = {};
    Walk fitting = walk;
    fitting.ls_weights = kNoWeights;
    LsFitter fitter;
    fitter.normal = normal.get();
    code<true>(Predictor::kLeastSquares, channels, fitting, fitter);
    PtmLeastSquaresFit local;
    PtmLeastSquaresFit& out = fit != nullptr ? *fit : local;
    solveLeastSquares(*normal, channels, true, out.weights);
    solveLeastSquares(*normal, channels, false, out.weights_without_estimate);
    out.fitted = true;
    std::memcpy(weights, without_estimate ? out.weights_without_estimate : out.weights,
                sizeof weights);
  }
  header.insert(header.end(), weights, weights + lsWeightBytes(channels));
  walk.ls_weights = reinterpret_cast<const int8_t*>(header.data() + kHeaderBytes);
  return walk;
}

// Coder 0's payload: the header, then per channel the residuals' zstd frame and (with a parent)
// the remainders', each after its u32 LE length.
Result<std::vector<uint8_t>> encodeZstd(const ImageView& tile, const EncodeOptions& options,
                                        const ParentTexels* parent, Predictor predictor,
                                        CodecScratch* scratch, PtmLeastSquaresFit* fit) {
  ScratchRef ref(scratch);
  PtmState& state = *ptmState(ref, CodecSide::kEncode);
  AxisMap columns, rows;
  std::vector<uint8_t> payload;
  TESSERA_ASSIGN_OR_RETURN(const Walk walk, prepareEncode(tile, parent, predictor, PtmCoder::kZstd,
                                                          state, fit, columns, rows, payload));
  const SymbolCounts counts = countSymbols(walk);
  PlaneCoder<true> planes = planesIn<true>(state.plane, tile.channels, counts);
  const PlaneCoder<true> starts = planes;
  code<true>(Predictor(payload[0]), tile.channels, walk, planes);
  const int level = options.effort != 0 ? options.effort : kDefaultZstdLevel;
  // The frames go to the zstd encoder's own buffer, so the planes stay valid throughout.
  auto addStream = [&](const uint8_t* symbols, size_t count) -> Result<void> {
    if (count == 0) {
      appendU32(payload, 0);
      return {};
    }
    TESSERA_ASSIGN_OR_RETURN(
        std::vector<uint8_t> frame,
        compressZstdFrame({symbols, count}, level, "ptm payload", state.zstd_encoder));
    appendU32(payload, uint32_t(frame.size()));
    payload.insert(payload.end(), frame.begin(), frame.end());
    return {};
  };
  for (uint32_t c = 0; c < tile.channels; ++c)
    TESSERA_TRY(addStream(starts.residuals[c], counts.coded));
  if (walk.parent != nullptr)
    for (uint32_t c = 0; c < tile.channels; ++c)
      TESSERA_TRY(addStream(starts.remainders[c], counts.derived));
  return payload;
}

// The model bytes of `coder` for the recorded symbols and their bits; coder 7's contexts share
// models where that costs little (lanes::kShareModelsSlack).
double chooseCoderModels(PtmCoder coder, const PtmRecording& recording,
                         std::vector<uint8_t>& params) {
  const double bits = rans::chooseModels(familyOf(coder), recording.counts, params);
  if (coder != PtmCoder::kRansLanes) return bits;
  return rans::shareModels(familyOf(coder), recording.counts, lanes::kShareModelsSlack, params);
}

double tableMinGainBytes(PtmCoder coder) {
  return coder == PtmCoder::kRansLanes ? lanes::kTableMinGainBytes : 0;
}

}  // namespace

Result<std::vector<uint8_t>> encodePtm(const ImageView& tile, const EncodeOptions& options,
                                       const ParentTexels* parent, Predictor predictor,
                                       PtmCoder coder, CodecScratch* scratch,
                                       PtmLeastSquaresFit* fit) {
  if (!isRansCoder(coder)) return encodeZstd(tile, options, parent, predictor, scratch, fit);
  PtmRecording recording;
  TESSERA_TRY(recordPtm(tile, parent, predictor, coder, scratch, fit, recording));
  return encodeRecordedPtm(recording, coder, scratch);
}

Result<size_t> estimatePtmBytes(const ImageView& tile, const EncodeOptions& options,
                                const ParentTexels* parent, Predictor predictor, PtmCoder coder,
                                CodecScratch* scratch, PtmLeastSquaresFit* fit) {
  if (!isRansCoder(coder)) {
    TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> payload,
                             encodeZstd(tile, options, parent, predictor, scratch, fit));
    return payload.size();
  }
  PtmRecording recording;
  TESSERA_TRY(recordPtm(tile, parent, predictor, coder, scratch, fit, recording));
  return estimateRecordedPtm(recording, coder);
}

Result<void> recordPtm(const ImageView& tile, const ParentTexels* parent, Predictor predictor,
                       PtmCoder coder, CodecScratch* scratch, PtmLeastSquaresFit* fit,
                       PtmRecording& recording) {
  if (!isRansCoder(coder))
    return fail(ErrorCode::kInvalidArgument, "ptm: only the rANS coders' walks are recorded");
  ScratchRef ref(scratch);
  PtmState& state = *ptmState(ref, CodecSide::kEncode);
  AxisMap columns, rows;
  TESSERA_ASSIGN_OR_RETURN(const Walk walk, prepareEncode(tile, parent, predictor, coder, state,
                                                          fit, columns, rows, recording.header));
  const uint32_t channels = tile.channels;
  recording.coder = coder;
  recording.channels = channels;
  recording.width = tile.width_px;
  recording.height = tile.height_px;
  recording.contexts = walk.parent != nullptr ? kParentContexts : kRootContexts;
  recording.green_led = false;
  const size_t symbols = size_t(tile.width_px) * tile.height_px * channels;
  recording.symbols.resize(symbols);
  recording.symbol_contexts.resize(symbols);
  uint8_t* const symbols_at = recording.symbols.data();
  uint8_t* const contexts_at = recording.symbol_contexts.data();
  const Predictor walked = Predictor(recording.header[0]);
  if (isErrorActivityCoder(coder)) {
    RansRecorder<true, true> recorder{{}, symbols_at, contexts_at};
    code<true>(walked, channels, walk, recorder);
  } else if (isChainedCoder(coder)) {
    RansRecorder<true, false> recorder{{}, symbols_at, contexts_at};
    code<true>(walked, channels, walk, recorder);
  } else {
    RansRecorder<false, false> recorder{{}, symbols_at, contexts_at};
    code<true>(walked, channels, walk, recorder);
  }
  recording.counts = rans::countByContext(recording.symbols, recording.symbol_contexts, channels,
                                          recording.contexts);
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
  const size_t states = coder == PtmCoder::kRansLanes ? lanes::headerBytes(recording.channels)
                                                      : 4 * recording.channels;
  return recording.header.size() + params.size() + tables.section.size() + size_t(tables.bits / 8) +
         states;
}

std::vector<uint8_t> encodeRecordedPtm(const PtmRecording& recording, PtmCoder coder,
                                       CodecScratch* scratch, const std::vector<uint8_t>* models,
                                       std::optional<double> table_min_gain_bytes) {
  TESSERA_CHECK(walksAlike(recording.coder, coder)) << "ptm: a recording of another walk";
  ScratchRef ref(scratch);
  PtmState& state = *ptmState(ref, CodecSide::kEncode);
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
  if (coder == PtmCoder::kRansLanes)
    lanes::encode(recording.symbols, recording.symbol_contexts, recording.width, recording.height,
                  recording.channels, recording.contexts, tables.context_models, payload);
  else
    rans::encode(familyOf(coder), recording.symbols, recording.symbol_contexts, recording.channels,
                 recording.contexts, tables.context_models, state.compressed, payload);
  return payload;
}

}  // namespace tessera::detail
