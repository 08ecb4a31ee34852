// ptm's lane coder, the decoders' shared half (ptm_lanes.h): the section's parsing, the SIMD
// decoder's symbol tables, and the scalar decoder, which is the texel walk in the lanes' order
// reading each lane's own state.
#include <algorithm>
#include <cstring>
#include <memory>

#include "format/byte_io.h"
#include "ptm/ptm_lanes.h"

namespace tessera::detail::ptm::lanes {

namespace {

// The walk's side that reads coder 7's streams: coder 1's contexts, one state per channel and
// row of the band (`lane`, set by the walk), a 16-bit word when a state falls below kLower, an
// escape's code from the channel's escape stream. At a stream's end it fails and reads zeros.
template <bool kGreenLedContexts>
struct LaneReader : WalkSide {
  static constexpr bool kContexts = true, kGreenLed = kGreenLedContexts;
  Streams* s;
  const rans::Model* const* models;  ///< [channel * contexts + context]
  uint32_t contexts;
  uint32_t lane = 0;
  bool bad = false;
  void residual(uint32_t c, uint32_t context, uint8_t& symbol) {
    symbol = read(c, *models[c * contexts + context]);
  }
  void remainder(uint32_t c, uint32_t context, uint8_t& symbol) {
    symbol = read(c, *models[c * contexts + kCodedContexts + context]);
  }
  bool failed() const { return bad; }
  uint8_t read(uint32_t c, const rans::Model& model) {
    uint32_t& x = s->states[c][lane];
    const uint32_t slot = x & (kScale - 1);
    const uint32_t symbol = model.bucket_symbol[slot];
    const uint32_t entry = model.entry[symbol];
    x = (entry >> 16) * (x >> kScaleBits) + slot - (entry & 0xffff);
    if (x < kLower) {
      if (s->words_end[c] - s->words[c] < 2) return fail();
      x = (x << 16) | uint32_t(s->words[c][0]) | uint32_t(s->words[c][1]) << 8;
      s->words[c] += 2;
    }
    uint32_t code = symbol;
    if (symbol == rans::kEscape) {
      if (s->escapes[c] == s->escapes_end[c]) return fail();
      code = *s->escapes[c]++;
      bad |= code < rans::kEscape;  // the encoder escapes only what 0..62 cannot say
    }
    return rans::unzigzag(code);
  }
  uint8_t fail() {
    bad = true;
    return 0;
  }
};

template <bool kGreenLed>
bool decodeScalar(Streams& streams, const Walk& walk, uint32_t channels, Predictor predictor,
                  std::span<const rans::Model* const> context_models) {
  LaneReader<kGreenLed> reader;
  reader.s = &streams;
  reader.models = context_models.data();
  reader.contexts = uint32_t(context_models.size() / channels);
  code<false>(predictor, channels, walk, reader);
  return !reader.failed();
}

// A model's kScale entries of the SIMD decoder's symbol table.
void fillSlots(const rans::Model& model, uint32_t* slots) {
  for (uint32_t symbol = 0; symbol < rans::kAlphabet; ++symbol) {
    const uint32_t freq = model.freq[symbol], first = symbol | freq << kFreqShift;
    uint32_t* run = slots + model.start[symbol];
    for (uint32_t i = 0; i < freq; ++i) run[i] = first + (i << kBiasShift);
  }
}

const uint32_t* familySlots() {
  static const std::unique_ptr<uint32_t[]> tables = [] {
    auto built = std::make_unique<uint32_t[]>(size_t(rans::kModelCount) * kScale);
    const rans::Model* family = rans::models(kFamily);
    for (uint32_t m = 0; m < rans::kModelCount; ++m)
      fillSlots(family[m], built.get() + size_t(m) * kScale);
    return built;
  }();
  return tables.get();
}

}  // namespace

bool parse(std::span<const uint8_t> section, uint32_t channels, size_t extra_bytes,
           std::vector<uint8_t>& padded, Streams& streams) {
  const size_t header = headerBytes(channels);
  if (section.size() < header) return false;
  const uint8_t* at = section.data();
  for (uint32_t c = 0; c < channels; ++c)
    for (uint32_t k = 0; k < kLanes; ++k, at += 4)
      if ((streams.states[c][k] = loadU32(at)) < kLower) return false;
  uint32_t lengths[4][2];
  size_t total = 0;
  for (uint32_t c = 0; c < channels; ++c)
    for (uint32_t i = 0; i < 2; ++i, at += 4) total += lengths[c][i] = loadU32(at);
  // Every byte belongs to a stream, and words are whole.
  if (total != section.size() - header) return false;
  for (uint32_t c = 0; c < channels; ++c)
    if (lengths[c][0] % 2 != 0) return false;
  padded.assign(total + 2 * channels * kPadding + extra_bytes, 0);
  uint8_t* to = padded.data();
  for (uint32_t c = 0; c < channels; ++c)
    for (uint32_t i = 0; i < 2; ++i) {
      std::memcpy(to, at, lengths[c][i]);
      (i == 0 ? streams.words : streams.escapes)[c] = to;
      (i == 0 ? streams.words_end : streams.escapes_end)[c] = to + lengths[c][i];
      at += lengths[c][i];
      to += lengths[c][i] + kPadding;
    }
  return true;
}

bool finished(const Streams& streams, uint32_t channels) {
  for (uint32_t c = 0; c < channels; ++c) {
    if (streams.words[c] != streams.words_end[c] || streams.escapes[c] != streams.escapes_end[c])
      return false;
    for (uint32_t k = 0; k < kLanes; ++k)
      if (streams.states[c][k] != kLower) return false;
  }
  return true;
}

bool simdAvailable() {
  static const bool available =
      __builtin_cpu_supports("avx2") != 0 && __builtin_cpu_supports("avx512f") != 0 &&
      __builtin_cpu_supports("avx512vl") != 0 && __builtin_cpu_supports("avx512bw") != 0 &&
      __builtin_cpu_supports("avx512dq") != 0;
  return available;
}

void slotModels(std::span<const rans::Model* const> context_models, SlotModels& out) {
  const rans::Model* family = rans::models(kFamily);
  uint32_t tables = 0;
  for (size_t i = 0; i < context_models.size(); ++i) {
    // Addresses, not pointers: a table's model lies in no array of the family's.
    const auto at = reinterpret_cast<uintptr_t>(context_models[i]);
    const bool in_family = at >= reinterpret_cast<uintptr_t>(family) &&
                           at < reinterpret_cast<uintptr_t>(family + rans::kModelCount);
    out.offsets[i] = int32_t(
        (in_family ? uint32_t(context_models[i] - family) : rans::kModelCount + tables++) * kScale);
  }
  if (tables == 0) {
    out.tables = familySlots();
    return;
  }
  // Each thread writes its tiles' tables behind its own copy of the family's entries: 4 MiB
  // copied once per decoding thread, where a copy of the tile's models would cost every tile.
  thread_local std::unique_ptr<uint32_t[]> with_room;
  if (with_room == nullptr) {
    with_room = std::make_unique_for_overwrite<uint32_t[]>(
        size_t(rans::kModelCount + 4 * kParentContexts) * kScale);
    std::memcpy(with_room.get(), familySlots(), size_t(rans::kModelCount) * kScale * 4);
  }
  for (size_t i = 0; i < context_models.size(); ++i)
    if (out.offsets[i] >= int32_t(rans::kModelCount * kScale))
      fillSlots(*context_models[i], with_room.get() + out.offsets[i]);
  out.tables = with_room.get();
}

bool decode(std::span<const uint8_t> section, const Walk& walk, uint32_t channels,
            Predictor predictor, std::span<const rans::Model* const> context_models, bool green_led,
            std::vector<uint8_t>& padded, Path path) {
  if (green_led && channels < 3) return false;
  if (path == Path::kFastest && simdAvailable())
    return avx512::decodeSimd(section, walk, channels, predictor, context_models, green_led,
                              padded);
  // The walk reads predictor 4's planes, which prepareWalk leaves out for the SIMD decoder.
  if (computesParentCorrectedEstimate(predictor, walk) && walk.upsampled == nullptr) return false;
  Streams streams;
  if (!parse(section, channels, 0, padded, streams)) return false;
  const bool decoded =
      green_led ? decodeScalar<true>(streams, walk, channels, predictor, context_models)
                : decodeScalar<false>(streams, walk, channels, predictor, context_models);
  return decoded && finished(streams, channels);
}

}  // namespace tessera::detail::ptm::lanes
