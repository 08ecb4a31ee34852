#pragma once
// What the lane coder's translation units share (ptm_lanes.h): ptm_lanes.cpp holds the encoder,
// the section's parsing and the scalar decoder every processor runs; ptm_lanes_simd.h the
// SIMD decoder (compiled for AVX2 and for AVX-512 by ptm_lanes_avx2.cpp and ptm_lanes_avx512.cpp),
// which runs the eight rows of a band in the lanes of a vector. Both decoders read each channel's
// words in the order of the band's rows at each step, so they consume the same bytes and agree on
// every texel; the tests hold them to it.

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "ptm/ptm_lanes.h"
#include "ptm/ptm_least_squares.h"

namespace tessera::detail::ptm::lanes {

inline constexpr uint32_t kScaleBits = rans::scaleBits(kFamily);
inline constexpr uint32_t kScale = 1u << kScaleBits;
static_assert(kScaleBits == rans::kBucketBits, "a slot's bucket must name its symbol");
// An escape's byte is the zigzag code itself (63..255), as the byte-wise coders' uniform 8 bits.
inline constexpr uint32_t kEscape = rans::kEscape;
// The SIMD decoder checks its streams' bounds every kCheckSteps steps, and in between reads at
// most 8 words and 8 escape bytes per channel and step, 16 bytes at a time.
inline constexpr uint32_t kCheckSteps = 16;
inline constexpr size_t kPadding = kCheckSteps * 16 + 16;

// The step at which lane `lane` of a band decodes column x, and the band's step count.
constexpr uint32_t stepOf(uint32_t x, uint32_t lane) {
  return x + 2 * lane;
}
constexpr uint32_t stepsPerBand(uint32_t width) {
  return width + 2 * (kLanes - 1);
}

// A band's parent table entry at step t (skewedParents), for a tile whose column_offset
// (decodeAvx2) is `column_offset`: lane k's block then lies in parent column
// column_offset / 2 + e - 1 - k. Entry 0 is the side texel of the first block's.
constexpr uint32_t bandParentEntry(uint32_t t, uint32_t column_offset) {
  return ((t + (column_offset & 1)) >> 1) + 1;
}
// The entries of a band's parent table, the last step's side texel's included, rounded up to
// whole transposes of eight.
constexpr uint32_t bandParentEntries(uint32_t width) {
  return (bandParentEntry(stepsPerBand(width) - 1, 1) + 2 + 7) / 8 * 8;
}

// The part of the parent tile a child's blocks cover, as the SIMD decoder lays it out: a copy
// without the tile's stride (the layout of predictor 4's block shortfalls; its texels are never
// copied), and the wider forms from which every predictor reads its blocks' parent texels.
struct ParentCopy {
  uint32_t stride = 0;        ///< bytes per row of the copy
  uint32_t first_row = 0;     ///< the parent row of the copy's first
  uint32_t first_column = 0;  ///< the parent column of the copy's first
  /// The copy's rows a 32-bit word per texel (bytes past the texel cleared), word j of a row
  /// being the texel at parent column column_offset / 2 - 8 + j, that is the copy's column
  /// clamped into the copy: skewedParents reads every lane's entries from it.
  const uint32_t* wide = nullptr;
  uint32_t wide_stride = 0;  ///< words per row of `wide`: bandParentEntries + 7
  /// Scratch for a band's parent tables, bandParentEntries x 8 words each: the blocks' rows',
  /// and predictor 5's rows beside them.
  uint32_t* band_block = nullptr;
  uint32_t* band_near = nullptr;
};

// A section's streams copied behind padding, so that a decoder may read up to kCheckSteps steps
// ahead of its bounds checks.
struct Streams {
  uint32_t states[4][kLanes];
  const uint8_t* words[4];
  const uint8_t* words_end[4];
  const uint8_t* escapes[4];
  const uint8_t* escapes_end[4];
};

// The walk's geometry and models as the decoders read them.
struct Geometry {
  uint8_t* texels;
  uint32_t width, height, channels;
  bool has_parent;
  bool nearest;        ///< predictor 1
  bool corrected;      ///< predictor 4, or 5 with predictor 4's estimate (usesEstimate)
  bool least_squares;  ///< predictor 5
  const ImageView* parent;
  const AxisMap* columns;
  const AxisMap* rows;
  const rans::Model* const* models;  // [channel * contexts + context]
  uint32_t contexts;
  const int16_t* upsampled;  ///< where `corrected`: the walk's planes
  int16_t* detail;
  /// Predictor 5 (with `corrected` where its ninth term, predictor 4's estimate, has a
  /// weight): the weights, [position][channel][term], and each position's and channel's sum.
  const int8_t* ls_weights;
  int ls_weight_sums[kLsSets][4];
  /// Red's and blue's contexts are green-led (leadByGreen).
  bool green_led = false;
};

/// Each position's and channel's sum of predictor 5's `weights` ([position][channel][term]).
void sumLeastSquaresWeights(const int8_t* weights, uint32_t channels, int (&sums)[kLsSets][4]);

/// Parses the lane section `section` into `streams`, copied into `padded` behind kPadding
/// bytes each, followed by `extra_bytes` of scratch for the caller; false when the section is
/// truncated or its lengths do not add up.
bool parse(std::span<const uint8_t> section, uint32_t channels, size_t extra_bytes,
           std::vector<uint8_t>& padded, Streams& streams);

/// True when every stream was consumed and every state is back at kLower.
bool finished(const Streams& streams, uint32_t channels);

/// The SIMD decoders' symbol table: per model of the family, per slot,
/// `symbol | (slot - start) << kBiasShift | freq << kFreqShift`, so that a lane finds all it
/// needs for a symbol in one lookup instead of two (slot to symbol, symbol to frequency and
/// start). 4 MiB, built on the first call (thread-safe), shared by both instruction sets.
inline constexpr uint32_t kSymbolBits = 6, kBiasShift = 6, kFreqShift = 18;
static_assert(rans::kAlphabet <= 1u << kSymbolBits && kFreqShift - kBiasShift >= kScaleBits);
const uint32_t* slotTables();

/// Where the SIMD decoders look up each context's model: `tables` holds kScale entries per
/// model as slotTables() does, and context i's model starts at entry `offsets[i]`. Without
/// explicit tables `tables` is slotTables() itself; with them, this thread's copy of it
/// followed by the tile's tables, so that one base and 32-bit offsets reach every model.
struct SlotModels {
  const uint32_t* tables = nullptr;
  int32_t offsets[4 * kParentContexts];
};

/// Lays out `context_models` (decode()'s) as SlotModels: a family model by its index, an
/// explicit table by the entries it is built into.
void slotModels(std::span<const rans::Model* const> context_models, SlotModels& out);

/// decode() on a SIMD path, one per instruction set, from the same source (ptm_lanes_simd.h):
/// the processor must have AVX2 (simdAvailable()), and for avx512::decodeSimd AVX-512 F, VL,
/// BW and DQ (avx512Available()), whose 32 vector registers spare the AVX2 build's spills.
namespace avx2 {
bool decodeSimd(std::span<const uint8_t> section, const Walk& walk, uint32_t channels,
                Predictor predictor, std::span<const rans::Model* const> context_models,
                bool green_led, std::vector<uint8_t>& padded);
}  // namespace avx2
namespace avx512 {
bool decodeSimd(std::span<const uint8_t> section, const Walk& walk, uint32_t channels,
                Predictor predictor, std::span<const rans::Model* const> context_models,
                bool green_led, std::vector<uint8_t>& padded);
}  // namespace avx512

}  // namespace tessera::detail::ptm::lanes
