// ptm's decoder (docs/codecs.md, "ptm (6)"): checks a payload's header, then runs the texel walk
// (ptm_walk.h) or the lanes (ptm_lanes.h) against the decoded parent.
#include <cstring>
#include <string>

#include <fmt/format.h>

#include "format/byte_io.h"
#include "ptm/ptm_codec.h"
#include "ptm/ptm_lanes.h"
#include "ptm/ptm_walk.h"

namespace tessera::detail {

using namespace ptm;

namespace {

// A payload's first bytes, checked: what the walk needs, and where the coder's part starts.
struct Header {
  Predictor predictor;
  PtmCoder coder;
  bool tables, green_led;
  int8_t ls_weights[lsWeightBytes(4)] = {};
  size_t body_at = kHeaderBytes;
};

Result<Header> readHeader(std::span<const uint8_t> payload, uint32_t channels,
                          const ParentTexels* parent) {
  if (payload.size() < kHeaderBytes)
    return fail(ErrorCode::kCorrupt,
                fmt::format("ptm payload: {} bytes, shorter than its header", payload.size()));
  Header h{Predictor(payload[0]), PtmCoder(payload[1] & ~(kPtmTablesFlag | kPtmGreenLedFlag)),
           (payload[1] & kPtmTablesFlag) != 0, (payload[1] & kPtmGreenLedFlag) != 0};
  const uint8_t coder = uint8_t(h.coder);
  // Format 1.0 removed them: no effort wrote them.
  if (payload[0] == 2)
    return fail(ErrorCode::kUnsupported,
                "ptm payload: predictor 2 (bilinear parent; removed in format 1.0) is not "
                "supported");
  if (coder == 5)
    return fail(ErrorCode::kUnsupported,
                "ptm payload: coder 5 (error energy without the parent; removed in format 1.0) "
                "is not supported");
  if (!isKeptPredictor(payload[0]))
    return fail(ErrorCode::kCorrupt, fmt::format("ptm payload: unknown predictor {}", payload[0]));
  // The tables flag goes with the rANS coders, the green-led flag with coder 7 of 3 or 4
  // channels.
  if (!isKeptCoder(coder) || (h.tables && !isRansCoder(h.coder)) ||
      (h.green_led && (h.coder != PtmCoder::kRansLanes || channels < 3)))
    return fail(
        ErrorCode::kCorrupt,
        fmt::format("ptm payload: unknown entropy coder {} for {} channels", payload[1], channels));
  if (h.predictor != Predictor::kRoot && parent == nullptr)
    return fail(ErrorCode::kCorrupt,
                "ptm payload: coded against a parent tile, but the tile has none (coarsest "
                "level)");
  if (h.predictor == Predictor::kLeastSquares) {
    if (payload.size() - kHeaderBytes < lsWeightBytes(channels))
      return fail(ErrorCode::kCorrupt,
                  fmt::format("ptm payload: {} bytes, shorter than its {} predictor weights",
                              payload.size(), lsWeightBytes(channels)));
    std::memcpy(h.ls_weights, payload.data() + kHeaderBytes, lsWeightBytes(channels));
    h.body_at += lsWeightBytes(channels);
    if (h.coder == PtmCoder::kRansLanes && usesEstimate(h.ls_weights, channels))
      return fail(ErrorCode::kUnsupported,
                  "ptm payload: coder 7 with a weight on predictor 5's estimate term (lanes; "
                  "removed in format 1.0) is not supported");
  }
  return h;
}

// Each (channel, context)'s model, channel-major: the model of `family` its byte names (any byte
// names one, so a corrupt byte shows only as a stream that does not finish cleanly), or the
// table the payload sends for it. Returns where the entropy-coded part starts.
Result<size_t> readContextModels(std::span<const uint8_t> payload, size_t body_at,
                                 uint32_t context_count, rans::FamilyId family_id, bool with_tables,
                                 std::vector<rans::Model>& table_models,
                                 const rans::Model** context_models) {
  if (payload.size() - body_at < context_count)
    return fail(ErrorCode::kCorrupt,
                fmt::format("ptm payload: {} bytes, shorter than its {} model parameters",
                            payload.size(), context_count));
  const rans::Model* family = rans::models(family_id);
  for (uint32_t i = 0; i < context_count; ++i) context_models[i] = &family[payload[body_at + i]];
  size_t stream_at = body_at + context_count;
  if (!with_tables) return stream_at;
  const size_t section =
      rans::readTables(payload.subspan(stream_at), context_count, rans::scaleBits(family_id),
                       table_models, std::span(context_models, context_count));
  if (section == 0)
    return fail(ErrorCode::kCorrupt,
                "ptm payload: explicit tables truncated, empty, or with a count outside 1..64 "
                "or padding bits set");
  return stream_at + section;
}

// A rANS coder's models and stream, decoded into walk.texels.
template <bool kChained, rans::FamilyId kFamily, bool kErrors = false>
Result<void> decodeRans(std::span<const uint8_t> payload, const Header& h, uint32_t channels,
                        uint32_t contexts, PtmState& state, const Walk& walk) {
  RansReader<kChained, rans::scaleBits(kFamily), kErrors> reader;
  const rans::Model* context_models[4 * kParentContexts];
  TESSERA_ASSIGN_OR_RETURN(const size_t stream_at,
                           readContextModels(payload, h.body_at, channels * contexts, kFamily,
                                             h.tables, state.tables, context_models));
  for (uint32_t c = 0; c < channels; ++c)
    for (uint32_t k = 0; k < contexts; ++k) reader.models[c][k] = context_models[c * contexts + k];
  if (!reader.decoder.start(payload.subspan(stream_at), channels))
    return fail(ErrorCode::kCorrupt,
                "ptm payload: rANS stream too short for its initial states, or one is out of "
                "range");
  code<false>(h.predictor, channels, walk, reader);
  if (!reader.decoder.finishedCleanly(channels))
    return fail(ErrorCode::kCorrupt,
                "ptm payload: rANS stream truncated, corrupt or followed by trailing bytes");
  return {};
}

// Coder 0: per channel a stream of residuals, then (with a parent) one of remainders, each a
// u32 LE length and a zstd frame of exactly the stream's symbol count (none when it is empty).
Result<void> decodeZstd(std::span<const uint8_t> payload, const Header& h, uint32_t channels,
                        PtmState& state, const Walk& walk) {
  const SymbolCounts counts = countSymbols(walk);
  PlaneCoder<false> planes = planesIn<false>(state.plane, channels, counts);
  size_t position = h.body_at;
  auto readStream = [&](uint8_t* symbols, size_t count, const char* what,
                        uint32_t channel) -> Result<void> {
    const std::string name = fmt::format("ptm payload: {} of channel {}", what, channel);
    if (payload.size() - position < 4)
      return fail(ErrorCode::kCorrupt, fmt::format("{}: truncated before its length", name));
    const uint32_t length = loadU32(payload.data() + position);
    position += 4;
    if (length > payload.size() - position)
      return fail(ErrorCode::kCorrupt, fmt::format("{} is {} bytes, only {} left", name, length,
                                                   payload.size() - position));
    if (count == 0) {
      if (length == 0) return {};
      return fail(ErrorCode::kCorrupt, fmt::format("{} must be empty", name));
    }
    TESSERA_TRY(decompressZstdFrame(payload.subspan(position, length), {symbols, count},
                                    name.c_str(), state.zstd_decoder));
    position += length;
    return {};
  };
  for (uint32_t c = 0; c < channels; ++c)
    TESSERA_TRY(readStream(planes.residuals[c], counts.coded, "residuals", c));
  if (walk.parent != nullptr)
    for (uint32_t c = 0; c < channels; ++c)
      TESSERA_TRY(readStream(planes.remainders[c], counts.derived, "remainders", c));
  if (position != payload.size())
    return fail(ErrorCode::kCorrupt,
                fmt::format("ptm payload: {} trailing bytes", payload.size() - position));
  code<false>(h.predictor, channels, walk, planes);
  return {};
}

}  // namespace

Result<void> decodePtm(std::span<const uint8_t> payload, Image& out, const ParentTexels* parent,
                       CodecScratch* scratch) {
  ScratchRef ref(scratch);
  PtmState& state = *ptmState(ref, CodecSide::kDecode);
  const uint32_t channels = out.channels;
  TESSERA_ASSIGN_OR_RETURN(const Header h, readHeader(payload, channels, parent));
  const bool lanes = h.coder == PtmCoder::kRansLanes;
  AxisMap columns, rows;
  TESSERA_ASSIGN_OR_RETURN(
      const Walk walk,
      prepareWalk(out.texels.data(), out.width_px, out.height_px, channels, parent, h.predictor,
                  h.coder, h.ls_weights, state, columns, rows, !(lanes && lanes::simdAvailable())));
  const uint32_t contexts = h.predictor != Predictor::kRoot ? kParentContexts : kRootContexts;
  using rans::FamilyId;
  switch (h.coder) {
    case PtmCoder::kZstd: return decodeZstd(payload, h, channels, state, walk);
    case PtmCoder::kRans:
      return decodeRans<false, FamilyId::kGeometric12>(payload, h, channels, contexts, state, walk);
    case PtmCoder::kRansChained:
      return decodeRans<true, FamilyId::kGeometric12>(payload, h, channels, contexts, state, walk);
    case PtmCoder::kRansMixture:
      return decodeRans<false, FamilyId::kMixture15>(payload, h, channels, contexts, state, walk);
    case PtmCoder::kRansMixtureChained:
      return decodeRans<true, FamilyId::kMixture15>(payload, h, channels, contexts, state, walk);
    case PtmCoder::kRansParentErrors:
      return decodeRans<true, FamilyId::kMixture15, true>(payload, h, channels, contexts, state,
                                                          walk);
    case PtmCoder::kRansLanes: break;
  }
  const rans::Model* context_models[4 * kParentContexts];
  TESSERA_ASSIGN_OR_RETURN(
      const size_t section_at,
      readContextModels(payload, h.body_at, contexts * channels, lanes::kFamily, h.tables,
                        state.tables, context_models));
  if (!lanes::decode(payload.subspan(section_at), walk, channels, h.predictor,
                     std::span(context_models, contexts * channels), h.green_led, state.plane))
    return fail(ErrorCode::kCorrupt,
                "ptm payload: lane streams truncated, corrupt or followed by trailing bytes");
  return {};
}

}  // namespace tessera::detail
