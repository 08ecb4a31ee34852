// ptm's decoder (docs/codecs.md, "ptm (6)"): checks a payload's header and streams, then runs
// the texel walk (ptm_walk.h) against the decoded parent.
#include <cstring>
#include <string>

#include <fmt/format.h>

#include "ptm/ptm_codec.h"
#include "ptm/ptm_lanes.h"
#include "ptm/ptm_least_squares.h"
#include "ptm/ptm_rans.h"
#include "ptm/ptm_walk.h"

namespace tessera::detail {

using namespace ptm;

namespace {

// Each (channel, context)'s model, channel-major, into `context_models`: the model of `family`
// its byte names (present: decodePtm checked), or with `with_tables` the table the payload
// sends for it. Returns where the entropy-coded part after them starts.
Result<size_t> readContextModels(std::span<const uint8_t> payload, size_t body_at,
                                 uint32_t context_count, rans::FamilyId family_id, bool with_tables,
                                 std::vector<rans::Model>& table_models,
                                 const rans::Model** context_models) {
  const rans::Model* family = rans::models(family_id);
  // Every parameter byte names a model, so a corrupt one shows only as a stream that does not
  // finish cleanly, and then only if its context is used.
  static_assert(rans::kModelCount == 256);
  for (uint32_t i = 0; i < context_count; ++i) context_models[i] = &family[payload[body_at + i]];
  size_t stream_at = body_at + context_count;
  if (with_tables) {
    const size_t section =
        rans::readTables(payload.subspan(stream_at), context_count, rans::scaleBits(family_id),
                         table_models, std::span(context_models, context_count));
    if (section == 0)
      return fail(ErrorCode::kCorrupt,
                  "ptm payload: explicit tables truncated, empty, or with a count outside 1..64 "
                  "or padding bits set");
    stream_at += section;
  }
  return stream_at;
}

// Decodes a rANS coder's model bytes (present: decodePtm checked) and stream into walk.texels.
template <bool kChained, rans::FamilyId kFamily, bool kErrors = false, bool kParent = false>
Result<void> decodeRans(std::span<const uint8_t> payload, size_t body_at, Predictor predictor,
                        uint32_t channels, uint32_t contexts, bool with_tables,
                        std::vector<rans::Model>& table_models, const Walk& walk) {
  RansReader<kChained, kFamily, kErrors, kParent> reader;
  const rans::Model* context_models[4 * kParentContexts];
  TESSERA_ASSIGN_OR_RETURN(const size_t stream_at,
                           readContextModels(payload, body_at, channels * contexts, kFamily,
                                             with_tables, table_models, context_models));
  for (uint32_t c = 0; c < channels; ++c)
    for (uint32_t k = 0; k < contexts; ++k) reader.models[c][k] = context_models[c * contexts + k];
  if (!reader.decoder.start(payload.subspan(stream_at), channels))
    return fail(ErrorCode::kCorrupt,
                "ptm payload: rANS stream too short for its initial states, or one is out of "
                "range");
  code<false>(predictor, channels, walk, reader);
  if (!reader.decoder.finishedCleanly(channels))
    return fail(ErrorCode::kCorrupt,
                "ptm payload: rANS stream truncated, corrupt or followed by trailing bytes");
  return {};
}

}  // namespace

Result<void> decodePtm(std::span<const uint8_t> payload, Image& out, const ParentTexels* parent,
                       CodecScratch* scratch) {
  ScratchRef ref(scratch);
  PtmState* state = ptmState(ref, CodecSide::kDecode);
  const uint32_t width = out.width_px, height = out.height_px, channels = out.channels;
  if (payload.size() < kHeaderBytes)
    return fail(ErrorCode::kCorrupt,
                fmt::format("ptm payload: {} bytes, shorter than its header", payload.size()));
  if (payload[0] > uint8_t(Predictor::kLeastSquares))
    return fail(ErrorCode::kCorrupt, fmt::format("ptm payload: unknown predictor {}", payload[0]));
  // The tables flag goes with the rANS coders only, the green-led flag with coder 7 of 3 or 4
  // channels.
  const bool with_tables = (payload[1] & kPtmTablesFlag) != 0;
  const bool green_led = (payload[1] & kPtmGreenLedFlag) != 0;
  const uint8_t coder_byte = payload[1] & uint8_t(~(kPtmTablesFlag | kPtmGreenLedFlag));
  if (coder_byte > uint8_t(PtmCoder::kRansLanes) ||
      (with_tables && !isRansCoder(PtmCoder(coder_byte))) ||
      (green_led && (coder_byte != uint8_t(PtmCoder::kRansLanes) || channels < 3)))
    return fail(
        ErrorCode::kCorrupt,
        fmt::format("ptm payload: unknown entropy coder {} for {} channels", payload[1], channels));
  const Predictor predictor = Predictor(payload[0]);
  const PtmCoder coder = PtmCoder(coder_byte);
  const bool has_parent = predictor != Predictor::kRoot;
  if (!codesPredictor(coder, predictor))
    return fail(
        ErrorCode::kCorrupt,
        fmt::format(
            "ptm payload: coder 7 (lanes) with predictor {}: it codes every predictor but 2",
            payload[0]));
  if (has_parent && parent == nullptr)
    return fail(ErrorCode::kCorrupt,
                "ptm payload: coded against a parent tile, but the tile has none (coarsest "
                "level)");
  // Predictor 5's weights follow the header; any byte is a valid weight.
  int8_t ls_weights[lsWeightBytes(4)] = {};
  size_t body_at = kHeaderBytes;
  if (predictor == Predictor::kLeastSquares) {
    if (payload.size() - kHeaderBytes < lsWeightBytes(channels))
      return fail(ErrorCode::kCorrupt,
                  fmt::format("ptm payload: {} bytes, shorter than its {} predictor weights",
                              payload.size(), lsWeightBytes(channels)));
    std::memcpy(ls_weights, payload.data() + kHeaderBytes, lsWeightBytes(channels));
    body_at += lsWeightBytes(channels);
  }
  AxisMap columns, rows;
  TESSERA_ASSIGN_OR_RETURN(
      const Walk walk,
      prepareWalk(out.texels.data(), width, height, channels, parent, predictor, coder, ls_weights,
                  *state, columns, rows,
                  !(coder == PtmCoder::kRansLanes && lanes::decodesWithoutPlanes())));

  const uint32_t contexts = has_parent ? kParentContexts : kRootContexts;
  const size_t params_bytes = size_t(contexts) * channels;
  if (isRansCoder(coder) && payload.size() - body_at < params_bytes)
    return fail(ErrorCode::kCorrupt,
                fmt::format("ptm payload: {} bytes, shorter than its {} model parameters",
                            payload.size(), params_bytes));
  using rans::FamilyId;
  switch (coder) {
    case PtmCoder::kZstd: break;
    case PtmCoder::kRans:
      return decodeRans<false, FamilyId::kGeometric12>(
          payload, body_at, predictor, channels, contexts, with_tables, state->ptm_tables, walk);
    case PtmCoder::kRansChained:
      return decodeRans<true, FamilyId::kGeometric12>(
          payload, body_at, predictor, channels, contexts, with_tables, state->ptm_tables, walk);
    case PtmCoder::kRansMixture:
      return decodeRans<false, FamilyId::kMixture15>(
          payload, body_at, predictor, channels, contexts, with_tables, state->ptm_tables, walk);
    case PtmCoder::kRansMixtureChained:
      return decodeRans<true, FamilyId::kMixture15>(payload, body_at, predictor, channels, contexts,
                                                    with_tables, state->ptm_tables, walk);
    case PtmCoder::kRansMixtureChainedErrors:
      return decodeRans<true, FamilyId::kMixture15, true>(
          payload, body_at, predictor, channels, contexts, with_tables, state->ptm_tables, walk);
    case PtmCoder::kRansParentErrors:
      return decodeRans<true, FamilyId::kMixture15, true, true>(
          payload, body_at, predictor, channels, contexts, with_tables, state->ptm_tables, walk);
    case PtmCoder::kRansLanes: {
      const rans::Model* context_models[4 * kParentContexts];
      TESSERA_ASSIGN_OR_RETURN(
          const size_t section_at,
          readContextModels(payload, body_at, uint32_t(params_bytes), lanes::kFamily, with_tables,
                            state->ptm_tables, context_models));
      if (!lanes::decode(payload.subspan(section_at), walk, channels, predictor,
                         std::span(context_models, params_bytes), green_led, state->plane))
        return fail(ErrorCode::kCorrupt,
                    "ptm payload: lane streams truncated, corrupt or followed by trailing bytes");
      return {};
    }
  }

  const SymbolCounts counts =
      countSymbols(width, height, has_parent ? &columns : nullptr, has_parent ? &rows : nullptr);
  PlaneCoder<false> planes = planesIn<false>(state->plane, channels, counts);
  size_t position = body_at;
  auto readStream = [&](uint8_t* symbols, size_t count, const char* what,
                        uint32_t channel) -> Result<void> {
    if (payload.size() - position < kStreamLengthBytes)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("ptm payload: truncated before the {} of channel {}", what, channel));
    uint32_t length = 0;
    for (size_t i = 0; i < kStreamLengthBytes; ++i)
      length |= uint32_t(payload[position + i]) << (8 * i);
    position += kStreamLengthBytes;
    if (length > payload.size() - position)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("ptm payload: {} of channel {} is {} bytes, only {} left", what,
                              channel, length, payload.size() - position));
    if (count == 0) {
      if (length != 0)
        return fail(ErrorCode::kCorrupt,
                    fmt::format("ptm payload: {} of channel {} must be empty", what, channel));
      return {};
    }
    const std::string name = fmt::format("ptm payload: {} of channel {}", what, channel);
    TESSERA_TRY(decompressZstdFrame(payload.subspan(position, length), {symbols, count},
                                    name.c_str(), state->zstd_decoder));
    position += length;
    return {};
  };
  for (uint32_t c = 0; c < channels; ++c)
    TESSERA_TRY(readStream(planes.residuals[c], counts.coded, "residuals", c));
  if (has_parent)
    for (uint32_t c = 0; c < channels; ++c)
      TESSERA_TRY(readStream(planes.remainders[c], counts.derived, "remainders", c));
  if (position != payload.size())
    return fail(ErrorCode::kCorrupt,
                fmt::format("ptm payload: {} trailing bytes", payload.size() - position));
  code<false>(predictor, channels, walk, planes);
  return {};
}

}  // namespace tessera::detail
