#pragma once
// ptm's lane coder (coder 7; docs/codecs.md, "ptm (6)", "Coder 7"): coder 1's symbols,
// contexts and model family in an order a decoder can run on eight rows at once. The tile is
// cut into bands of eight rows; in each band row k codes texel x = t - 2k at step t (the walk's
// lane order, ptm_walk.h), so every neighbour a texel reads was decoded at an earlier step.
// Each (channel, row of the band) has its own rANS state, renormalised by 16-bit words from one
// word stream per channel, and escaped residuals are plain bytes of an escape stream per
// channel: eight texels' symbols of a channel decode with the same instructions. The decoders
// are ptm_lanes.cpp (the walk, on any processor) and ptm_lanes_avx512.cpp (SIMD); the encoder
// is ptm_lanes_encode.cpp (tessera::encoders).

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "ptm/ptm_rans.h"
#include "ptm/ptm_walk.h"

namespace tessera::detail::ptm::lanes {

inline constexpr uint32_t kLanes = kLaneRows;
/// States lie in [kLower, 2^32); every state starts (encoder) and ends (decoder) at kLower.
inline constexpr uint32_t kLower = 1u << 16;
/// Family 1, whose 12-bit slots name their symbol in one lookup.
inline constexpr rans::FamilyId kFamily = rans::FamilyId::kGeometric12;
inline constexpr uint32_t kScaleBits = rans::scaleBits(kFamily);
inline constexpr uint32_t kScale = 1u << kScaleBits;
static_assert(kScaleBits == rans::kBucketBits, "a slot's bucket must name its symbol");

/// What an explicit table must save beyond its bytes: the SIMD decoder builds each into 4096
/// entries (16 KiB) before the tile, about 2.5 us of a 256-px tile's 300.
inline constexpr double kTableMinGainBytes = 256;
/// Contexts share a model where that costs at most this share of their bits plus a byte
/// (rans::shareModels): every distinct model is 16 KiB of the SIMD decoder's cache.
inline constexpr double kShareModelsSlack = 0.03;

/// Bytes of the section's header: each (channel, lane) state, then per channel the lengths of
/// its word stream and its escape stream, u32 LE each.
constexpr size_t headerBytes(uint32_t channels) {
  return size_t(channels) * (kLanes * 4 + 2 * 4);
}

/// How decode() runs: the fastest the processor allows, or (tests) the walk.
enum class Path : uint8_t { kFastest, kScalar };
/// True where decode(kFastest) takes the SIMD decoder: AVX-512 F, VL, BW and DQ.
bool simdAvailable();

/// Decodes the lane section `section` into walk.texels: the walk prepareWalk made for
/// `predictor` (with planes where the SIMD decoder will not run); `context_models` holds each
/// (channel, context)'s model, channel-major, of family kFamily or an explicit table at its
/// scale; `green_led` says red's and blue's contexts follow green (3 or 4 channels); `padded`
/// is scratch. False when the section is truncated or corrupt: a state out of range, a stream
/// not consumed exactly, an escape of a residual that needed none.
bool decode(std::span<const uint8_t> section, const Walk& walk, uint32_t channels,
            Predictor predictor, std::span<const rans::Model* const> context_models, bool green_led,
            std::vector<uint8_t>& padded, Path path = Path::kFastest);

/// Encoder (ptm_lanes_encode.cpp): rewrites the contexts a coder-1 walk recorded (`channels`
/// per texel, 3 or 4) to the green-led ones.
void leadByGreen(std::span<const uint8_t> symbols, std::span<uint8_t> contexts, uint32_t channels);
/// Encoder: appends the lane section of a tile whose symbols and contexts a coder-1 walk
/// recorded in raster order, each coded under `context_models[channel * contexts_per_channel
/// + context]`.
void encode(std::span<const uint8_t> symbols, std::span<const uint8_t> contexts, uint32_t width,
            uint32_t height, uint32_t channels, uint32_t contexts_per_channel,
            std::span<const rans::Model* const> context_models, std::vector<uint8_t>& out);

// What the two decoders share.

/// The SIMD decoder checks its streams' bounds every kCheckSteps steps and in between reads at
/// most 8 words and 8 escape bytes per channel and step, 16 bytes at a time.
inline constexpr uint32_t kCheckSteps = 16;
inline constexpr size_t kPadding = kCheckSteps * 16 + 16;

/// A section's states and streams, each stream copied in front of kPadding bytes.
struct Streams {
  uint32_t states[4][kLanes];
  const uint8_t* words[4];
  const uint8_t* words_end[4];
  const uint8_t* escapes[4];
  const uint8_t* escapes_end[4];
};
/// Parses `section` into `streams`, copied into `padded`, which ends with `extra_bytes` of
/// scratch; false when it is truncated or its lengths do not add up.
bool parse(std::span<const uint8_t> section, uint32_t channels, size_t extra_bytes,
           std::vector<uint8_t>& padded, Streams& streams);
/// True when every stream was consumed and every state is back at kLower.
bool finished(const Streams& streams, uint32_t channels);

/// The SIMD decoder's symbol table: per model, per slot, `symbol | (slot - start) << kBiasShift |
/// freq << kFreqShift`, all a lane needs in one lookup. Context i's model starts at entry
/// `offsets[i]` of `tables`: the family's (4 MiB, built once), or where the payload sends
/// tables, this thread's copy of them followed by the tables.
inline constexpr uint32_t kSymbolBits = 6, kBiasShift = 6, kFreqShift = 18;
struct SlotModels {
  const uint32_t* tables = nullptr;
  int32_t offsets[4 * kParentContexts];
};
void slotModels(std::span<const rans::Model* const> context_models, SlotModels& out);

namespace avx512 {
/// decode() on the SIMD path; the processor must have it (simdAvailable()).
bool decodeSimd(std::span<const uint8_t> section, const Walk& walk, uint32_t channels,
                Predictor predictor, std::span<const rans::Model* const> context_models,
                bool green_led, std::vector<uint8_t>& padded);
}  // namespace avx512

}  // namespace tessera::detail::ptm::lanes
