// ptm's lane coder, the SIMD decoder (ptm_lanes.h): the eight rows of a band in the 32-bit lanes
// of a 256-bit vector, each lane's texel a byte per channel, so that the neighbours are rotated
// once for all channels, the activity is byte-wise absolute differences summed by
// multiply-adds, and the median is taken byte-wise. Compiled for AVX-512 (F, VL, BW, DQ) on
// 256-bit vectors: its 32 registers hold the step loop that spilled a quarter of its
// instructions with AVX2's 16, and its masks pick models and words. Elsewhere decode() runs
// the walk. It reads each channel's words in the band's row order at each step, as the walk
// does, so both consume the same bytes and agree on every texel; the tests hold them to it.
#include <immintrin.h>

#include <algorithm>
#include <cstddef>
#include <cstring>
#include <utility>

#include "ptm/ptm_lanes.h"

#define TESSERA_AVX512 __attribute__((target("avx2,avx512f,avx512vl,avx512bw,avx512dq")))
#define TESSERA_AVX512_INLINE TESSERA_AVX512 __attribute__((always_inline)) inline

namespace tessera::detail::ptm::lanes::avx512 {

namespace {

static_assert(kLanes == 8, "a band's rows are the eight 32-bit lanes of a vector");
constexpr uint32_t kGroups = kParentContexts / kActivityClasses;  // block positions, remainders
constexpr uint32_t kLsPairs = 5;  // predictor 5's terms in pairs, and the weights' sum

// The step at which lane k decodes column x; a band's parent table entry at step t for a tile
// whose first column lies at `column_offset` in its parent's children (lane k's block then
// lies in parent column column_offset / 2 + e - 1 - k; entry 0 is the first block's side).
constexpr uint32_t stepOf(uint32_t x, uint32_t lane) {
  return x + 2 * lane;
}
constexpr uint32_t bandParentEntry(uint32_t t, uint32_t column_offset) {
  return ((t + (column_offset & 1)) >> 1) + 1;
}
// A band's table entries, the last step's side texel's included, in whole transposes of eight.
constexpr uint32_t bandParentEntries(uint32_t width) {
  return (bandParentEntry(stepsPerBand(width) - 1, 1) + 2 + 7) / 8 * 8;
}

// --- vector operations ----------------------------------------------------------------------

// What _mm256_i32gather_epi32(base, offsets, kScale) returns, from eight scalar loads: where
// the gather is microcoded (AMD Zen 4: 11-12 cycles against about 5) this is faster.
template <int kScale>
TESSERA_AVX512_INLINE __m256i gather32(const void* base, __m256i offsets) {
  const auto* bytes = static_cast<const uint8_t*>(base);
  auto load = [bytes](uint64_t pair, int high) {
    int32_t value;
    std::memcpy(&value, bytes + ptrdiff_t(int32_t(uint32_t(pair >> (32 * high)))) * kScale, 4);
    return value;
  };
  const __m128i low_half = _mm256_castsi256_si128(offsets);
  const __m128i high_half = _mm256_extracti128_si256(offsets, 1);
  const auto l01 = uint64_t(_mm_cvtsi128_si64(low_half));
  const auto l23 = uint64_t(_mm_extract_epi64(low_half, 1));
  const auto h01 = uint64_t(_mm_cvtsi128_si64(high_half));
  const auto h23 = uint64_t(_mm_extract_epi64(high_half, 1));
  __m128i low = _mm_cvtsi32_si128(load(l01, 0));
  low = _mm_insert_epi32(low, load(l01, 1), 1);
  low = _mm_insert_epi32(low, load(l23, 0), 2);
  low = _mm_insert_epi32(low, load(l23, 1), 3);
  __m128i high = _mm_cvtsi32_si128(load(h01, 0));
  high = _mm_insert_epi32(high, load(h01, 1), 1);
  high = _mm_insert_epi32(high, load(h23, 0), 2);
  high = _mm_insert_epi32(high, load(h23, 1), 3);
  return _mm256_inserti128_si256(_mm256_castsi128_si256(low), high, 1);
}

TESSERA_AVX512_INLINE __m256i load(const void* from) {
  return _mm256_loadu_si256(static_cast<const __m256i*>(from));
}
TESSERA_AVX512_INLINE __m256i channelOf(__m256i bytes, uint32_t c) {
  return _mm256_and_si256(_mm256_srli_epi32(bytes, int(8 * c)), _mm256_set1_epi32(0xff));
}
TESSERA_AVX512_INLINE __m256i clampToByte(__m256i v) {
  return _mm256_min_epi32(_mm256_set1_epi32(0xff), _mm256_max_epi32(_mm256_setzero_si256(), v));
}
// LOCO-I's median of each lane's a, b and a + b - c (medPredict).
TESSERA_AVX512_INLINE __m256i median(__m256i a, __m256i b, __m256i c) {
  const __m256i low = _mm256_min_epi32(a, b), high = _mm256_max_epi32(a, b);
  return _mm256_min_epi32(high, _mm256_max_epi32(low, _mm256_sub_epi32(_mm256_add_epi32(a, b), c)));
}
// The same median of each byte: low + min(max(high - c, 0), high - low), since
// a + b - c = low + (high - c) lies between low and high exactly when c does.
TESSERA_AVX512_INLINE __m256i medianBytes(__m256i a, __m256i b, __m256i c) {
  const __m256i low = _mm256_min_epu8(a, b), high = _mm256_max_epu8(a, b);
  return _mm256_add_epi8(low,
                         _mm256_min_epu8(_mm256_subs_epu8(high, c), _mm256_sub_epi8(high, low)));
}
TESSERA_AVX512_INLINE __m256i absDifference(__m256i a, __m256i b) {
  return _mm256_sub_epi8(_mm256_max_epu8(a, b), _mm256_min_epu8(a, b));
}

// Each lane's left, up, up-left and up-right values from its values of the last three steps
// (`back1` the latest): the row above's are lane k - 1's rotated into lane k, lane 0's come from
// the band before (`up0`, `up_left0`, `up_right0`), with neighbourOffsets' substitutes.
struct LaneNeighbours {
  __m256i left, up, up_left, up_right;
};
TESSERA_AVX512_INLINE LaneNeighbours laneNeighbours(__m256i back1, __m256i back2, __m256i back3,
                                                    bool first_band, __m256i up0, __m256i up_left0,
                                                    __m256i up_right0, __m256i first_column,
                                                    __m256i last_column) {
  const __m256i rotate = _mm256_setr_epi32(7, 0, 1, 2, 3, 4, 5, 6);
  const __m256i l = back1;
  __m256i u = _mm256_permutevar8x32_epi32(back2, rotate);
  __m256i ul = _mm256_permutevar8x32_epi32(back3, rotate);
  __m256i ur = _mm256_permutevar8x32_epi32(back1, rotate);
  // Row 0: every neighbour is the left one.
  u = _mm256_blend_epi32(u, first_band ? l : up0, 1);
  ul = _mm256_blend_epi32(ul, first_band ? l : up_left0, 1);
  ur = _mm256_blend_epi32(ur, first_band ? l : up_right0, 1);
  return {_mm256_blendv_epi8(l, u, first_column), u, _mm256_blendv_epi8(ul, u, first_column),
          _mm256_blendv_epi8(ur, u, last_column)};
}

// Channel c of each lane's texels `low` and `high` as the low and high 16 bits of the lane.
TESSERA_AVX512_INLINE __m256i channelPair(__m256i low, __m256i high, __m256i low_mask,
                                          __m256i high_mask) {
  return _mm256_or_si256(_mm256_shuffle_epi8(low, low_mask), _mm256_shuffle_epi8(high, high_mask));
}

// --- the parent, laid out before the bands ---------------------------------------------------

// The part of the parent tile the blocks cover and its forms: the copy's layout (predictor 4's
// shortfalls), its rows a 32-bit word per texel, and each band's tables of parent texels by step.
struct ParentCopy {
  uint32_t stride = 0;        ///< bytes per row of the copy
  uint32_t first_row = 0;     ///< the parent row of the copy's first
  uint32_t first_column = 0;  ///< the parent column of the copy's first
  /// The copy's rows a word per texel: word j is parent column columns.parent[0] - 8 + j,
  /// clamped into the copy.
  const uint32_t* wide = nullptr;
  uint32_t wide_stride = 0;        ///< words per row of `wide`
  uint32_t* band_block = nullptr;  ///< bandParentEntries x 8 words: the blocks' parent rows
  uint32_t* band_near = nullptr;   ///< the same of the rows beside them (predictors 4 and 5)
};

// A band's parent texels by step, so that a step reads its lanes' with one aligned load: lane k
// of entry e is word e + 7 - k of the wide copy's row `wide_rows[k]`. Eight entries at a time:
// each lane's eight words, skewed by one per lane, transposed.
TESSERA_AVX512 void skewedParents(const ParentCopy& parent, const int32_t* wide_rows,
                                  uint32_t entries, uint32_t* out) {
  for (uint32_t e0 = 0; e0 < entries; e0 += 8) {
    __m256i r[8], pairs[8], quads[8];
    for (uint32_t k = 0; k < 8; ++k)
      r[k] = load(parent.wide + size_t(wide_rows[k]) * parent.wide_stride + e0 + 7 - k);
    for (uint32_t k = 0; k < 8; k += 2) {
      pairs[k] = _mm256_unpacklo_epi32(r[k], r[k + 1]);
      pairs[k + 1] = _mm256_unpackhi_epi32(r[k], r[k + 1]);
    }
    for (uint32_t k = 0; k < 8; k += 4) {
      quads[k] = _mm256_unpacklo_epi64(pairs[k], pairs[k + 2]);
      quads[k + 1] = _mm256_unpackhi_epi64(pairs[k], pairs[k + 2]);
      quads[k + 2] = _mm256_unpacklo_epi64(pairs[k + 1], pairs[k + 3]);
      quads[k + 3] = _mm256_unpackhi_epi64(pairs[k + 1], pairs[k + 3]);
    }
    auto* to = reinterpret_cast<__m256i*>(out + size_t(e0) * 8);
    for (uint32_t j = 0; j < 4; ++j) {
      _mm256_store_si256(to + j, _mm256_permute2x128_si256(quads[j], quads[4 + j], 0x20));
      _mm256_store_si256(to + 4 + j, _mm256_permute2x128_si256(quads[j], quads[4 + j], 0x31));
    }
  }
}

// `count` texels of `channels` bytes as 32-bit words, the bytes past a texel's cleared, four
// texels per instruction, reading no byte past the last texel's.
TESSERA_AVX512 void widenTexels(const uint8_t* texels, uint32_t channels, uint32_t count,
                                uint32_t* out) {
  uint32_t i = 0;
  auto* to = reinterpret_cast<__m128i*>(out);
  if (channels == 4) {
    std::memcpy(out, texels, size_t(count) * 4);
    return;
  }
  if (channels == 3) {
    const __m128i spread = _mm_setr_epi8(0, 1, 2, -1, 3, 4, 5, -1, 6, 7, 8, -1, 9, 10, 11, -1);
    for (; 3 * i + 16 <= 3 * count; i += 4)
      _mm_storeu_si128(
          to + i / 4,
          _mm_shuffle_epi8(
              _mm_loadu_si128(reinterpret_cast<const __m128i*>(texels + 3 * size_t(i))), spread));
  } else if (channels == 2) {
    for (; i + 4 <= count; i += 4)
      _mm_storeu_si128(to + i / 4, _mm_cvtepu16_epi32(_mm_loadl_epi64(
                                       reinterpret_cast<const __m128i*>(texels + 2 * size_t(i)))));
  } else {
    for (; i + 4 <= count; i += 4) {
      int32_t four;
      std::memcpy(&four, texels + i, sizeof four);
      _mm_storeu_si128(to + i / 4, _mm_cvtepu8_epi32(_mm_cvtsi32_si128(four)));
    }
  }
  for (; i < count; ++i) {
    uint32_t word = 0;
    std::memcpy(&word, texels + size_t(i) * channels, channels);
    out[i] = word;
  }
}

// Entry `e` of a band's parent table (skewedParents).
TESSERA_AVX512_INLINE __m256i bandParents(const uint32_t* table, uint32_t e) {
  return _mm256_load_si256(reinterpret_cast<const __m256i*>(table + size_t(e) * 8));
}

// The 16 bytes of four words (four texels of a wide row, every channel) as 16-bit lanes.
TESSERA_AVX512_INLINE __m256i bytesAs16(const uint32_t* words) {
  return _mm256_cvtepu8_epi16(_mm_loadu_si128(reinterpret_cast<const __m128i*>(words)));
}

// Predictor 4's shortfall of each block wholly in the tile, per channel, at its parent texel's
// place in the copy: 16 (4P + 1.5) less its four texels' upsampled values. With each child's
// W = 9 P + 3 Ph + 3 Pv + Pd + 6, a block sums to 36 P + 6 (Pl + Pr + Pu + Pd) + (its four
// diagonal texels) + 24, so the shortfall is 28 P - 6 (Pl + Pr + Pu + Pd) - (Pul + Pur + Pdl +
// Pdr): four blocks and every channel at once in 16-bit lanes, from the wide rows, whose
// padding holds mapAxis's clamped neighbours.
TESSERA_AVX512 void blockShortfalls(const Walk& walk, uint32_t channels, const ParentCopy& parent,
                                    uint32_t parent_rows, int16_t* shortfall) {
  std::fill_n(shortfall, size_t(parent_rows) * parent.stride, int16_t(0));
  const AxisMap& columns = *walk.columns;
  const AxisMap& rows = *walk.rows;
  // The blocks wholly in the tile have first children every other column from `first` to `last`.
  uint32_t first = walk.width, last = 0;
  for (uint32_t x = 0; x + 1 < walk.width; ++x)
    if (columns.full[x] != 0 && columns.second[x] == 0) {
      first = std::min(first, x);
      last = x;
    }
  if (first > last) return;
  const uint32_t first_block = columns.parent[first], blocks = (last - first) / 2 + 1;
  const uint32_t at = first_block - columns.parent[0] + 8;
  const __m256i six = _mm256_set1_epi16(6), twenty_eight = _mm256_set1_epi16(28);
  auto wideRow = [&](uint32_t row) {
    return parent.wide + size_t(row - parent.first_row) * parent.wide_stride + at;
  };
  for (uint32_t y = 0; y + 1 < walk.height; ++y) {
    if (rows.full[y] == 0 || rows.second[y] != 0) continue;
    const uint32_t* m = wideRow(rows.parent[y]);
    const uint32_t* a = wideRow(rows.neighbour[y]);
    const uint32_t* b = wideRow(rows.neighbour[y + 1]);
    int16_t* out = shortfall + size_t(rows.parent[y] - parent.first_row) * parent.stride +
                   size_t(first_block - parent.first_column) * channels;
    for (uint32_t i = 0; i < blocks; i += 4) {
      const __m256i sides =
          _mm256_add_epi16(_mm256_add_epi16(bytesAs16(m + i - 1), bytesAs16(m + i + 1)),
                           _mm256_add_epi16(bytesAs16(a + i), bytesAs16(b + i)));
      const __m256i corners =
          _mm256_add_epi16(_mm256_add_epi16(bytesAs16(a + i - 1), bytesAs16(a + i + 1)),
                           _mm256_add_epi16(bytesAs16(b + i - 1), bytesAs16(b + i + 1)));
      const __m256i g =
          _mm256_sub_epi16(_mm256_sub_epi16(_mm256_mullo_epi16(bytesAs16(m + i), twenty_eight),
                                            _mm256_mullo_epi16(sides, six)),
                           corners);
      alignas(32) int16_t g4[16];
      _mm256_store_si256(reinterpret_cast<__m256i*>(g4), g);
      for (uint32_t k = 0; k < 4 && i + k < blocks; ++k)
        std::memcpy(out + size_t(i + k) * channels, g4 + 4 * k, channels * sizeof(int16_t));
    }
  }
}

// --- the decoder ----------------------------------------------------------------------------

// Which predictor the lanes run: 0 and 3 (the median), 1, 4, or 5 without predictor 4's term.
enum class LanePredictor : uint8_t { kMedian, kNearest, kCorrected, kLeastSquares };

// The walk's geometry and models as the decoder reads them.
struct Geometry {
  uint8_t* texels;
  uint32_t width, height, channels;
  bool has_parent;
  const AxisMap* columns;
  const AxisMap* rows;
  const rans::Model* const* models;  ///< [channel * contexts + context]
  uint32_t contexts;
  const int8_t* ls_weights;  ///< predictor 5: [position][channel][term]
  int ls_sums[kLsSets][4];
};

// What every step of a tile reads from memory: the arrays a lane's class or the step's parity
// indexes. The class bounds too: the compiler otherwise rebuilt them from immediates at every
// step, for want of registers. Each channel's model offsets by context group, eight classes
// each: a lane picks its model with a permute. Green-led: green's frequency of 0 and red's and
// blue's models after a zero green residual and after any other, per position group.
template <uint32_t kCh, bool kGreenLed>
struct TileTables {
  alignas(32) int32_t bounds[kActivityClasses - 1][kLanes];
  __m256i group_models[kCh][kGroups];
  __m256i green_zero_freqs[kGroups - 1];
  __m256i led_models[kGreenLed ? kCh : 1][2][kGroups - 1];
};

// What every step of a tile reads from registers (a structure apart from the arrays above, so
// that the compiler keeps its fields in registers).
template <uint32_t kCh>
struct TileConstants {
  __m256i low_masks[kCh], high_masks[kCh];  ///< channel c of each lane to its low, high 16 bits
  uint32_t column_offset;  ///< the first column's place among its parent's children
  bool first_column_partial, last_column_partial;  ///< predictor 4 pulls no texel there
};

template <uint32_t kCh, bool kGreenLed>
TESSERA_AVX512_INLINE void setUpModels(const Geometry& g, const SlotModels& models,
                                       TileTables<kCh, kGreenLed>& tc) {
  for (uint32_t c = 0; c < kCh; ++c)
    for (uint32_t group = 0; group < kGroups; ++group)
      tc.group_models[c][group] = group * kActivityClasses < g.contexts
                                      ? load(models.offsets + c * g.contexts + group * 8)
                                      : _mm256_setzero_si256();
  if constexpr (kGreenLed)
    for (uint32_t group = 0; group + 1 < kGroups; ++group) {
      alignas(32) int32_t freqs[kLanes] = {}, after[2][kCh][kLanes] = {};
      for (uint32_t k = 0; k < kActivityClasses && group * kActivityClasses < g.contexts; ++k) {
        freqs[k] = g.models[kGreenChannel * g.contexts + group * kActivityClasses + k]->freq[0];
        for (uint32_t zero_green = 0; zero_green < 2; ++zero_green)
          for (uint32_t c = 0; c < kCh; ++c)
            after[zero_green][c][k] = models.offsets[c * g.contexts + group * kActivityClasses +
                                                     greenLedClass(k, zero_green != 0)];
      }
      tc.green_zero_freqs[group] = load(freqs);
      for (uint32_t zero_green = 0; zero_green < 2; ++zero_green)
        for (uint32_t c = 0; c < kCh; ++c)
          tc.led_models[c][zero_green][group] = load(after[zero_green][c]);
    }
}

template <uint32_t kCh, bool kGreenLed>
TESSERA_AVX512_INLINE void setUpTile(const Geometry& g, const SlotModels& models, bool corrected,
                                     TileTables<kCh, kGreenLed>& tables, TileConstants<kCh>& tc) {
  for (uint32_t i = 0; i < kActivityClasses - 1; ++i)
    std::fill_n(tables.bounds[i], kLanes, kActivityBounds[i] * int(g.channels) - 1);
  setUpModels(g, models, tables);
  for (uint32_t c = 0; c < kCh; ++c) {
    alignas(32) int8_t low[32], high[32];
    for (uint32_t i = 0; i < 32; ++i) {
      const auto byte = int8_t(i / 4 % 4 * 4 + c);
      low[i] = i % 4 == 0 ? byte : int8_t(-1);
      high[i] = i % 4 == 2 ? byte : int8_t(-1);
    }
    tc.low_masks[c] = load(low);
    tc.high_masks[c] = load(high);
  }
  // Child column x lies in parent column (x + offset) / 2 (mapAxis), so the lanes of a step,
  // whose columns differ by even numbers, are all first children of their blocks or all second.
  tc.column_offset = g.has_parent ? 2 * g.columns->parent[0] + g.columns->second[0] : 0;
  tc.first_column_partial = corrected && g.columns->full.front() == 0;
  tc.last_column_partial = corrected && g.columns->full.back() == 0;
}

// What every step of a band reads.
template <uint32_t kCh>
struct BandConstants {
  uint32_t y0, rows;
  bool first_band;
  __m256i row_in, second_row, second_row_table, derived_row, full_row;
  __m256i parent_rows;  ///< predictor 4: each lane's parent row's offset in the copy
};
// Predictor 5: per step parity and channel, each lane's weight pairs for its block position.
template <uint32_t kCh>
using BandWeights = __m256i[2][kCh][kLsPairs];

template <uint32_t kCh, LanePredictor kPredictor>
TESSERA_AVX512_INLINE void setUpBand(const Geometry& g, const ParentCopy& parent, uint32_t y0,
                                     BandConstants<kCh>& band, BandWeights<kCh>& ls_pairs) {
  constexpr bool kSides =
      kPredictor == LanePredictor::kCorrected || kPredictor == LanePredictor::kLeastSquares;
  band.y0 = y0;
  band.rows = std::min(kLanes, g.height - y0);
  band.first_band = y0 == 0;
  band.row_in = _mm256_cmpgt_epi32(_mm256_set1_epi32(int(band.rows)),
                                   _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
  alignas(32) int32_t at[kLanes] = {}, second[kLanes] = {}, derived[kLanes] = {}, full[kLanes] = {},
                      wide_rows[kLanes] = {}, near_rows[kLanes] = {};
  for (uint32_t k = 0; k < band.rows && g.has_parent; ++k) {
    const uint32_t y = y0 + k;
    at[k] = int32_t((g.rows->parent[y] - parent.first_row) * parent.stride);
    second[k] = g.rows->second[y] != 0 ? -1 : 0;
    derived[k] = g.rows->derived[y] != 0 ? -1 : 0;
    full[k] = g.rows->full[y] != 0 ? -1 : 0;
    wide_rows[k] = int32_t(g.rows->parent[y] - parent.first_row);
    near_rows[k] = int32_t(g.rows->neighbour[y] - parent.first_row);
  }
  band.parent_rows = load(at);
  band.second_row = load(second);
  // The second table's bit in a two-table permute's index, in the lanes of second rows.
  band.second_row_table = _mm256_and_si256(band.second_row, _mm256_set1_epi32(8));
  band.derived_row = load(derived);
  band.full_row = load(full);
  // Lanes past the tile's last row read row 0's parents.
  if (g.has_parent) {
    skewedParents(parent, wide_rows, bandParentEntries(g.width), parent.band_block);
    if constexpr (kSides)
      skewedParents(parent, near_rows, bandParentEntries(g.width), parent.band_near);
  }
  if constexpr (kPredictor == LanePredictor::kLeastSquares)
    for (uint32_t column = 0; column < 2; ++column)
      for (uint32_t c = 0; c < kCh; ++c) {
        const int8_t* first = g.ls_weights + (column * kCh + c) * kLsTerms;
        const int8_t* second_row = g.ls_weights + ((2 + column) * kCh + c) * kLsTerms;
        auto pair = [](int low, int high) { return int(uint16_t(low)) | high << 16; };
        for (uint32_t k = 0; k < kLsPairs; ++k) {
          const bool sum = k == kLsPairs - 1;
          ls_pairs[column][c][k] = _mm256_blendv_epi8(
              _mm256_set1_epi32(sum ? pair(-g.ls_sums[column][c], 64)
                                    : pair(first[2 * k], first[2 * k + 1])),
              _mm256_set1_epi32(sum ? pair(-g.ls_sums[2 + column][c], 64)
                                    : pair(second_row[2 * k], second_row[2 * k + 1])),
              band.second_row);
        }
      }
}

// What a step knows before its symbols: which lanes decode which texels, the neighbours, the
// activity classes, and the blocks' parent texels (P, and Ph, Pv and Pd beside it).
struct Step {
  uint32_t t, second_column;
  __m256i xs, active, first_column, last_column, derived;
  int derived_mask;
  __m256i left, up, up_left, up_right, medians, activity_class;
  __m256i parents, side_parents, near_parents, diagonal_parents;
};

// The last three steps' values of each lane (latest first) and, for predictor 4, each channel's
// departures from the upsampled parent.
template <uint32_t kCh>
struct History {
  __m256i back[3];
  __m256i detail[3][kCh];
  __m256i previous_shortfalls[(kCh + 1) / 2];
};

template <uint32_t kCh, LanePredictor kPredictor, bool kGreenLed>
TESSERA_AVX512_INLINE Step stepAt(uint32_t t, const Geometry& g,
                                  const TileTables<kCh, kGreenLed>& tables,
                                  const TileConstants<kCh>& tc, const BandConstants<kCh>& band,
                                  const History<kCh>& history, const uint32_t* above,
                                  const ParentCopy& parent) {
  constexpr bool kSides =
      kPredictor == LanePredictor::kCorrected || kPredictor == LanePredictor::kLeastSquares;
  const __m256i zero = _mm256_setzero_si256();
  Step s;
  s.t = t;
  s.xs = _mm256_sub_epi32(_mm256_set1_epi32(int(t)), _mm256_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14));
  s.active = _mm256_and_si256(
      _mm256_andnot_si256(_mm256_cmpgt_epi32(zero, s.xs),
                          _mm256_cmpgt_epi32(_mm256_set1_epi32(int(g.width)), s.xs)),
      band.row_in);
  s.first_column = _mm256_cmpeq_epi32(s.xs, zero);
  s.last_column = _mm256_cmpeq_epi32(s.xs, _mm256_set1_epi32(int(g.width) - 1));
  // Lane 0's row above is the last lane's of the band before (row 0 takes substitutes).
  const auto [left, up, up_left, up_right] = laneNeighbours(
      history.back[0], history.back[1], history.back[2], band.first_band,
      _mm256_set1_epi32(int(above[0])), _mm256_set1_epi32(int(above[-ptrdiff_t(kLanes)])),
      _mm256_set1_epi32(int(above[kLanes])), s.first_column, s.last_column);
  s.left = left, s.up = up, s.up_left = up_left, s.up_right = up_right;
  // All channels at once, a byte each: three absolute differences summed by multiply-adds.
  const __m256i ones8 = _mm256_set1_epi8(1);
  const __m256i activity = _mm256_madd_epi16(
      _mm256_add_epi16(_mm256_add_epi16(_mm256_maddubs_epi16(absDifference(left, up_left), ones8),
                                        _mm256_maddubs_epi16(absDifference(up, up_left), ones8)),
                       _mm256_maddubs_epi16(absDifference(up_right, up), ones8)),
      _mm256_set1_epi16(1));
  s.medians = medianBytes(left, up, up_left);
  s.activity_class = zero;
#pragma GCC unroll 8
  for (const auto& bound : tables.bounds)
    s.activity_class =
        _mm256_sub_epi32(s.activity_class, _mm256_cmpgt_epi32(activity, load(bound)));
  s.second_column = g.has_parent ? (t + tc.column_offset) & 1 : 0;
  s.derived = zero;
  if (g.has_parent && s.second_column != 0)
    s.derived = _mm256_and_si256(_mm256_and_si256(band.derived_row, s.active),
                                 _mm256_cmpgt_epi32(s.xs, zero));
  s.derived_mask = _mm256_movemask_ps(_mm256_castsi256_ps(s.derived));
  const uint32_t entry = bandParentEntry(t, tc.column_offset);
  const uint32_t side = s.second_column != 0 ? entry + 1 : entry - 1;
  s.parents = s.side_parents = s.near_parents = s.diagonal_parents = zero;
  // Predictors 1, 4 and 5 read P at every step, the others for derived texels only.
  if (kPredictor != LanePredictor::kMedian || s.derived_mask != 0)
    s.parents = bandParents(parent.band_block, entry);
  if constexpr (kSides) {
    s.side_parents = bandParents(parent.band_block, side);
    s.near_parents = bandParents(parent.band_near, entry);
    s.diagonal_parents = bandParents(parent.band_near, side);
  }
  return s;
}

// Predictor 4 (parentCorrectedEstimate) per channel: W, the upsampled parent 9 P + 3 Ph + 3 Pv +
// Pd + 6, in two multiply-adds of channel pairs, plus the median departure, plus eq. 3's pull
// written from the block's shortfall G = 16 (4P + 1.5) - (Wa + Wb + Wc + Wd): a's is
// (G - 4δ) >> 3, b's (G - D(a) - 3δ) / 12, c's (G - D(a) - D(b) - 2δ) >> 2, the walk's integers
// since D(t) = 16 t - W(t). The division towards zero is a single-precision one truncated,
// exact because |G| <= 16344 and |D|, |δ| <= 4086. `detail_above` is lane 0's row above in the
// band before, per channel (History).
template <uint32_t kCh>
TESSERA_AVX512_INLINE void correctedPredictions(
    const Step& s, const Geometry& g, const TileConstants<kCh>& tc, const BandConstants<kCh>& band,
    const ParentCopy& parent, const int* shortfalls, const int32_t* detail_above,
    size_t detail_words, History<kCh>& history, __m256i* upsampled, __m256i* predicted) {
  const __m256i zero = _mm256_setzero_si256();
#pragma GCC unroll 4
  for (uint32_t c = 0; c < kCh; ++c)
    upsampled[c] = _mm256_add_epi32(
        _mm256_add_epi32(_mm256_madd_epi16(channelPair(s.parents, s.side_parents, tc.low_masks[c],
                                                       tc.high_masks[c]),
                                           _mm256_set1_epi32(9 | 3 << 16)),
                         _mm256_madd_epi16(channelPair(s.near_parents, s.diagonal_parents,
                                                       tc.low_masks[c], tc.high_masks[c]),
                                           _mm256_set1_epi32(3 | 1 << 16))),
        _mm256_set1_epi32(6));
  // Where the block sum pulls: the lanes whose blocks lie wholly in the tile.
  __m256i partial = zero;
  if (tc.first_column_partial) partial = s.first_column;
  if (tc.last_column_partial) partial = _mm256_or_si256(partial, s.last_column);
  const __m256i pulled = _mm256_andnot_si256(partial, _mm256_and_si256(band.full_row, s.active));
  // Two channels' int16 shortfalls per gather at each lane's block (idle lanes' columns kept in
  // the tile); a block's second column has its first's.
  __m256i shortfall[kCh];
  const bool same_block = s.second_column != 0 && s.t > 0;
  const __m256i column = _mm256_srli_epi32(
      _mm256_add_epi32(
          _mm256_min_epi32(_mm256_max_epi32(s.xs, zero), _mm256_set1_epi32(int(g.width) - 1)),
          _mm256_set1_epi32(int(tc.column_offset))),
      1);
  const __m256i block_at = _mm256_add_epi32(
      band.parent_rows,
      _mm256_mullo_epi32(_mm256_sub_epi32(column, _mm256_set1_epi32(int(parent.first_column))),
                         _mm256_set1_epi32(int(kCh))));
  for (uint32_t c = 0; c < kCh; c += 2) {
    const __m256i both =
        same_block ? history.previous_shortfalls[c / 2]
                   : gather32<2>(shortfalls, _mm256_add_epi32(block_at, _mm256_set1_epi32(int(c))));
    history.previous_shortfalls[c / 2] = both;
    shortfall[c] = _mm256_srai_epi32(_mm256_slli_epi32(both, 16), 16);
    if (c + 1 < kCh) shortfall[c + 1] = _mm256_srai_epi32(both, 16);
  }
#pragma GCC unroll 4
  for (uint32_t c = 0; c < kCh; ++c) {
    const int32_t* above = detail_above + c * detail_words;
    auto up0 = [&](ptrdiff_t at)
                   TESSERA_AVX512 { return band.first_band ? zero : _mm256_set1_epi32(above[at]); };
    const auto [dl, du, dul, dur] = laneNeighbours(
        history.detail[0][c], history.detail[1][c], history.detail[2][c], band.first_band, up0(0),
        up0(-ptrdiff_t(kLanes)), up0(kLanes), s.first_column, s.last_column);
    const __m256i departure = median(dl, du, dul);
    __m256i pull;
    if (s.second_column == 0) {
      const __m256i first =
          _mm256_srai_epi32(_mm256_sub_epi32(shortfall[c], _mm256_slli_epi32(departure, 2)), 3);
      const __m256i second = _mm256_srai_epi32(
          _mm256_sub_epi32(_mm256_sub_epi32(_mm256_sub_epi32(shortfall[c], du), dur),
                           _mm256_slli_epi32(departure, 1)),
          2);
      pull = _mm256_and_si256(_mm256_blendv_epi8(first, second, band.second_row), pulled);
    } else {
      const __m256i n =
          _mm256_sub_epi32(_mm256_sub_epi32(shortfall[c], dl),
                           _mm256_add_epi32(_mm256_slli_epi32(departure, 1), departure));
      pull = _mm256_and_si256(
          _mm256_cvttps_epi32(_mm256_div_ps(_mm256_cvtepi32_ps(n), _mm256_set1_ps(12.0f))),
          _mm256_andnot_si256(band.second_row, pulled));
    }
    const __m256i estimate = _mm256_add_epi32(_mm256_add_epi32(upsampled[c], departure), pull);
    predicted[c] =
        clampToByte(_mm256_srai_epi32(_mm256_add_epi32(estimate, _mm256_set1_epi32(8)), 4));
  }
}

// Predictor 5 without predictor 4's term (leastSquaresPredictFactored) per channel: each
// multiply-add sums two terms, (L, U), (UL, UR), (P, Ph), (Pv, Pd) and (m, 1) with the weights'
// pairs, the last -Σw and 64; that is Σ w v - m Σw + 64, the factored sum plus its rounding over
// 16, shifted by 4 bits less.
template <uint32_t kCh>
TESSERA_AVX512_INLINE void leastSquaresPredictions(const Step& s, const TileConstants<kCh>& tc,
                                                   const BandWeights<kCh>& ls_pairs,
                                                   __m256i* predicted) {
#pragma GCC unroll 4
  for (uint32_t c = 0; c < kCh; ++c) {
    const __m256i* pairs = ls_pairs[s.second_column][c];
    const __m256i low = tc.low_masks[c], high = tc.high_masks[c];
    const __m256i median_and_one =
        _mm256_or_si256(_mm256_shuffle_epi8(s.medians, low), _mm256_set1_epi32(1 << 16));
    const __m256i neighbours = _mm256_add_epi32(
        _mm256_madd_epi16(channelPair(s.left, s.up, low, high), pairs[0]),
        _mm256_madd_epi16(channelPair(s.up_left, s.up_right, low, high), pairs[1]));
    const __m256i parents = _mm256_add_epi32(
        _mm256_madd_epi16(channelPair(s.parents, s.side_parents, low, high), pairs[2]),
        _mm256_madd_epi16(channelPair(s.near_parents, s.diagonal_parents, low, high), pairs[3]));
    const __m256i sixteenths = _mm256_add_epi32(_mm256_add_epi32(neighbours, parents),
                                                _mm256_madd_epi16(median_and_one, pairs[4]));
    predicted[c] = clampToByte(_mm256_add_epi32(
        channelOf(s.medians, c), _mm256_srai_epi32(sixteenths, kLsProductShift - 4)));
  }
}

// Each channel's symbols of the step: every lane's model by a permute of its class (the block
// position's group, or the remainders' for derived lanes), one lookup of its slot's entry, the
// state's update, and the words the lanes that fall below kLower read, by a masked compare and
// an expand of the next eight words, without a branch on whether any lane reads (as good as
// random: mispredicted, it cost more than the load, which the padding allows at every step).
template <uint32_t kCh, bool kGreenLed>
TESSERA_AVX512_INLINE void decodeSymbols(const Step& s, const Geometry& g,
                                         const TileTables<kCh, kGreenLed>& tc,
                                         const BandConstants<kCh>& band, const int* slot_tables,
                                         __m256i* state, const uint8_t** words_at,
                                         __m256i* symbols) {
  const __m256i slot_mask = _mm256_set1_epi32(int(kScale - 1));
  const auto active = __mmask8(_mm256_movemask_ps(_mm256_castsi256_ps(s.active)));
  // One permute of two tables: the class picks the entry, the row's parity the table.
  auto byClass = [&](const __m256i* groups) TESSERA_AVX512 {
    return g.has_parent
               ? _mm256_permutex2var_epi32(groups[s.second_column],
                                           _mm256_or_si256(s.activity_class, band.second_row_table),
                                           groups[2 + s.second_column])
               : _mm256_permutevar8x32_epi32(groups[s.second_column], s.activity_class);
  };
  // Green-led: green's symbol is 0 where its slot lies below its model's frequency of 0, whose
  // slots come first, so red's and blue's models are known before green's lookup.
  __m256i green_zero = _mm256_setzero_si256();
  if constexpr (kGreenLed)
    green_zero = _mm256_cmpgt_epi32(byClass(tc.green_zero_freqs),
                                    _mm256_and_si256(state[kGreenChannel], slot_mask));
#pragma GCC unroll 4
  for (uint32_t c = 0; c < kCh; ++c) {
    __m256i model = byClass(tc.group_models[c]);
    if (kGreenLed && followsGreen(c))
      model = _mm256_blendv_epi8(byClass(tc.led_models[c][0]), byClass(tc.led_models[c][1]),
                                 green_zero);
    if (s.derived_mask != 0)
      model = _mm256_mask_permutexvar_epi32(model, __mmask8(s.derived_mask), s.activity_class,
                                            tc.group_models[c][kGroups - 1]);
    const __m256i slot = _mm256_and_si256(state[c], slot_mask);
    const __m256i entry = gather32<4>(slot_tables, _mm256_add_epi32(model, slot));
    __m256i next =
        _mm256_add_epi32(_mm256_mullo_epi32(_mm256_srli_epi32(entry, kFreqShift),
                                            _mm256_srli_epi32(state[c], kScaleBits)),
                         _mm256_and_si256(_mm256_srli_epi32(entry, kBiasShift), slot_mask));
    next = _mm256_mask_blend_epi32(active, state[c], next);
    const __mmask8 reads = _mm256_mask_cmplt_epu32_mask(active, next, _mm256_set1_epi32(kLower));
    const __m256i words =
        _mm256_cvtepu16_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(words_at[c])));
    state[c] = _mm256_mask_or_epi32(next, reads, _mm256_slli_epi32(next, 16),
                                    _mm256_maskz_expand_epi32(reads, words));
    words_at[c] += 2 * __builtin_popcount(unsigned(reads));
    symbols[c] = _mm256_and_si256(entry, _mm256_set1_epi32((1 << kSymbolBits) - 1));
  }
}

// Escaped lanes take their codes from their channels' escape streams, in lane order; a code
// below 63 marks the stream corrupt. One test for any channel first (63 is the largest symbol).
template <uint32_t kCh>
TESSERA_AVX512_INLINE void decodeEscapes(const Step& s, const uint8_t** escapes_at,
                                         __m256i* symbols, __m256i& failed) {
  const __m256i escape = _mm256_set1_epi32(int(rans::kEscape));
  __m256i largest = symbols[0];
#pragma GCC unroll 4
  for (uint32_t c = 1; c < kCh; ++c) largest = _mm256_max_epu32(largest, symbols[c]);
  if (_mm256_testz_si256(_mm256_cmpeq_epi32(largest, escape), s.active)) [[likely]]
    return;
#pragma GCC unroll 4
  for (uint32_t c = 0; c < kCh; ++c) {
    const auto escaped = _mm256_mask_cmpeq_epi32_mask(
        __mmask8(_mm256_movemask_ps(_mm256_castsi256_ps(s.active))), symbols[c], escape);
    if (escaped == 0) continue;
    const __m256i bytes =
        _mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(escapes_at[c])));
    const __m256i mine = _mm256_maskz_expand_epi32(escaped, bytes);
    symbols[c] = _mm256_mask_blend_epi32(escaped, symbols[c], mine);
    failed =
        _mm256_or_si256(failed, _mm256_maskz_mov_epi32(escaped, _mm256_cmpgt_epi32(escape, mine)));
    escapes_at[c] += __builtin_popcount(unsigned(escaped));
  }
}

// The step's texels: residuals zigzagged back and put in bytes, subtract-green undone bytewise,
// plus the prediction; derived lanes by eq. 3, d = 4P + remainder - a - b - c with the
// remainder the guess expects (the median's, predictor 5's at position 3; none for predictor 1).
template <uint32_t kCh, LanePredictor kPredictor>
TESSERA_AVX512_INLINE __m256i stepValues(const Step& s, const __m256i* symbols,
                                         const __m256i* predicted) {
  const __m256i zero = _mm256_setzero_si256(), byte_mask = _mm256_set1_epi32(0xff);
  __m256i residual[kCh], coded = zero;
#pragma GCC unroll 4
  for (uint32_t c = 0; c < kCh; ++c) {
    residual[c] = _mm256_xor_si256(
        _mm256_srli_epi32(symbols[c], 1),
        _mm256_sub_epi32(zero, _mm256_and_si256(symbols[c], _mm256_set1_epi32(1))));
    coded = _mm256_or_si256(
        coded, _mm256_slli_epi32(_mm256_and_si256(residual[c], byte_mask), int(8 * c)));
  }
  if constexpr (kCh >= 3)
    coded = _mm256_add_epi8(
        coded, _mm256_shuffle_epi8(coded, _mm256_setr_epi8(1, -1, 1, -1, 5, -1, 5, -1, 9, -1, 9, -1,
                                                           13, -1, 13, -1, 1, -1, 1, -1, 5, -1, 5,
                                                           -1, 9, -1, 9, -1, 13, -1, 13, -1)));
  __m256i prediction = s.medians;
  if constexpr (kPredictor == LanePredictor::kNearest) prediction = s.parents;
  if constexpr (kPredictor == LanePredictor::kCorrected ||
                kPredictor == LanePredictor::kLeastSquares) {
    prediction = zero;
#pragma GCC unroll 4
    for (uint32_t c = 0; c < kCh; ++c)
      prediction = _mm256_or_si256(prediction, _mm256_slli_epi32(predicted[c], int(8 * c)));
  }
  const __m256i values = _mm256_add_epi8(prediction, coded);
  if (s.derived_mask == 0) return values;
  __m256i remainders = zero;
#pragma GCC unroll 4
  for (uint32_t c = 0; c < kCh; ++c) {
    const __m256i sum3 = _mm256_add_epi32(
        _mm256_add_epi32(channelOf(s.left, c), channelOf(s.up, c)), channelOf(s.up_left, c));
    const __m256i four_parent = _mm256_slli_epi32(channelOf(s.parents, c), 2);
    const __m256i guess =
        kPredictor == LanePredictor::kLeastSquares ? predicted[c] : channelOf(s.medians, c);
    const __m256i expected =
        kPredictor == LanePredictor::kNearest
            ? zero
            : _mm256_min_epi32(
                  _mm256_set1_epi32(3),
                  _mm256_max_epi32(zero,
                                   _mm256_sub_epi32(_mm256_add_epi32(guess, sum3), four_parent)));
    const __m256i remainder = _mm256_and_si256(
        _mm256_add_epi32(_mm256_add_epi32(_mm256_sub_epi32(four_parent, sum3), expected),
                         residual[c]),
        byte_mask);
    remainders = _mm256_or_si256(remainders, _mm256_slli_epi32(remainder, int(8 * c)));
  }
  return _mm256_blendv_epi8(values, remainders, s.derived);
}

// The band's texels from its steps into rows: eight at a time (a gather of a row's texels,
// kLanes words apart, packed to kCh bytes each) while the 32 bytes stored stay in the row, then
// four bytes a texel (the next overwrites what spills), then byte by byte.
template <uint32_t kCh>
TESSERA_AVX512_INLINE void storeBand(const Geometry& g, const BandConstants<kCh>& band,
                                     const uint32_t* diagonal) {
  alignas(32) int8_t pack_bytes[32];
  for (uint32_t i = 0; i < 16; ++i)
    pack_bytes[i] = pack_bytes[16 + i] = i < 4 * kCh ? int8_t(i / kCh * 4 + i % kCh) : int8_t(-1);
  alignas(32) int32_t halves[8];
  for (uint32_t i = 0; i < 8; ++i) halves[i] = int32_t(i < kCh ? i : i < 2 * kCh ? i - kCh + 4 : 7);
  const __m256i pack = load(pack_bytes), pack_halves = load(halves);
  const __m256i octet_at = _mm256_setr_epi32(0, 8, 16, 24, 32, 40, 48, 56);
  const uint32_t width = g.width;
  // Octets whose 32 bytes end inside the row, then texels whose four bytes do.
  const uint32_t octets = width * kCh >= 32 ? (width * kCh - 32) / kCh / 8 + 1 : 0;
  const uint32_t whole = width * kCh >= 4 ? (width * kCh - 4) / kCh + 1 : 0;
  for (uint32_t k = 0; k < band.rows; ++k) {
    uint8_t* row = g.texels + size_t(band.y0 + k) * width * kCh;
    const uint32_t* from = diagonal + size_t(stepOf(0, k)) * kLanes + k;
    for (uint32_t i = 0; i < octets; ++i, row += 8 * kCh, from += 8 * kLanes)
      _mm256_storeu_si256(reinterpret_cast<__m256i*>(row),
                          _mm256_permutevar8x32_epi32(
                              _mm256_shuffle_epi8(gather32<4>(from, octet_at), pack), pack_halves));
    for (uint32_t x = 8 * octets; x < whole; ++x, row += kCh, from += kLanes)
      std::memcpy(row, from, 4);
    for (uint32_t x = std::max(whole, 8 * octets); x < width; ++x, row += kCh, from += kLanes)
      for (uint32_t c = 0; c < kCh; ++c) row[c] = uint8_t(*from >> (8 * c));
  }
}

// Where decodeBands works: the streams, the models, the parent's forms, each band's texels by
// step (`diagonal`, from which lane 0 reads the band before's last lane) and predictor 4's
// departures likewise per channel, and its block shortfalls.
struct Scratch {
  Streams* streams;
  const SlotModels* models;
  const ParentCopy* parent;
  uint32_t* diagonal;
  int32_t* detail_diagonal;
  const int16_t* shortfall;
};

template <uint32_t kCh, LanePredictor kPredictor, bool kGreenLed>
TESSERA_AVX512 bool decodeBands(const Geometry& geometry, const Scratch& scratch) {
  constexpr bool kCorrected = kPredictor == LanePredictor::kCorrected;
  // Locals, not the structures' fields, which every vector store may alias.
  const Geometry g = geometry;
  Streams& streams = *scratch.streams;
  const ParentCopy parent = *scratch.parent;
  uint32_t* const diagonal = scratch.diagonal;
  int32_t* const detail_diagonal = scratch.detail_diagonal;
  const int* const shortfalls = reinterpret_cast<const int*>(scratch.shortfall);
  const int* const slot_tables = reinterpret_cast<const int*>(scratch.models->tables);
  const uint32_t steps = stepsPerBand(g.width);
  const size_t diagonal_words = size_t(steps + stepOf(1, kLanes - 1)) * kLanes;
  TileTables<kCh, kGreenLed> tables;
  TileConstants<kCh> tc;
  setUpTile(g, *scratch.models, kCorrected, tables, tc);
  const uint8_t* words_at[kCh];
  const uint8_t* escapes_at[kCh];
  __m256i state[kCh];
#pragma GCC unroll 4
  for (uint32_t c = 0; c < kCh; ++c) {
    words_at[c] = streams.words[c];
    escapes_at[c] = streams.escapes[c];
    state[c] = load(streams.states[c]);
  }
  __m256i failed = _mm256_setzero_si256();
  for (uint32_t y0 = 0; y0 < g.height; y0 += kLanes) {
    BandConstants<kCh> band;
    BandWeights<kCh> ls_pairs;
    setUpBand<kCh, kPredictor>(g, parent, y0, band, ls_pairs);
    History<kCh> history{};
    for (uint32_t t = 0; t < steps; ++t) {
      // Lane 0's row above: the band before's last lane, whose steps lie ahead of this one's.
      const size_t above_at = size_t(stepOf(t, kLanes - 1)) * kLanes + (kLanes - 1);
      const Step s =
          stepAt<kCh, kPredictor>(t, g, tables, tc, band, history, diagonal + above_at, parent);
      __m256i predicted[kCh], upsampled[kCh];
      if constexpr (kCorrected)
        correctedPredictions(s, g, tc, band, parent, shortfalls, detail_diagonal + above_at,
                             diagonal_words, history, upsampled, predicted);
      if constexpr (kPredictor == LanePredictor::kLeastSquares)
        leastSquaresPredictions(s, tc, ls_pairs, predicted);
      __m256i symbols[kCh];
      decodeSymbols(s, g, tables, band, slot_tables, state, words_at, symbols);
      decodeEscapes<kCh>(s, escapes_at, symbols, failed);
      const __m256i values = stepValues<kCh, kPredictor>(s, symbols, predicted);
      history.back[2] = history.back[1];
      history.back[1] = history.back[0];
      history.back[0] = values;
      _mm256_storeu_si256(reinterpret_cast<__m256i*>(diagonal + size_t(t) * kLanes), values);
      if constexpr (kCorrected)
#pragma GCC unroll 4
        for (uint32_t c = 0; c < kCh; ++c) {
          history.detail[2][c] = history.detail[1][c];
          history.detail[1][c] = history.detail[0][c];
          history.detail[0][c] =
              _mm256_sub_epi32(_mm256_slli_epi32(channelOf(values, c), 4), upsampled[c]);
          _mm256_storeu_si256(
              reinterpret_cast<__m256i*>(detail_diagonal + c * diagonal_words + size_t(t) * kLanes),
              history.detail[0][c]);
        }
      // A corrupt stream may run ahead: stop within kCheckSteps of passing its end.
      if (t % kCheckSteps == kCheckSteps - 1 || t + 1 == steps)
#pragma GCC unroll 4
        for (uint32_t c = 0; c < kCh; ++c)
          if (words_at[c] > streams.words_end[c] || escapes_at[c] > streams.escapes_end[c])
            return false;
    }
    storeBand(g, band, diagonal);
  }
#pragma GCC unroll 4
  for (uint32_t c = 0; c < kCh; ++c) {
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(streams.states[c]), state[c]);
    streams.words[c] = words_at[c];
    streams.escapes[c] = escapes_at[c];
  }
  return _mm256_testz_si256(failed, failed) != 0;
}

template <LanePredictor kPredictor>
bool decodeWith(uint32_t channels, bool green_led, const Geometry& g, const Scratch& scratch) {
  switch (channels) {
    case 1: return decodeBands<1, kPredictor, false>(g, scratch);
    case 2: return decodeBands<2, kPredictor, false>(g, scratch);
    case 3:
      return green_led ? decodeBands<3, kPredictor, true>(g, scratch)
                       : decodeBands<3, kPredictor, false>(g, scratch);
    default:
      return green_led ? decodeBands<4, kPredictor, true>(g, scratch)
                       : decodeBands<4, kPredictor, false>(g, scratch);
  }
}

// The parent texels the blocks read (for predictors 4 and 5 those beside them too), as
// ParentCopy lays them out: the range, then the wide rows in `wide`.
void copyParent(const Walk& walk, uint32_t channels, bool sides, ParentCopy& parent,
                uint32_t& parent_rows) {
  auto range = [&](const AxisMap& axis) {
    uint32_t first = axis.parent.front(), last = axis.parent.back();
    for (uint32_t i = 0; sides && i < axis.neighbour.size(); ++i) {
      first = std::min(first, axis.neighbour[i]);
      last = std::max(last, axis.neighbour[i]);
    }
    return std::pair{first, last};
  };
  const auto [first_row, last_row] = range(*walk.rows);
  const auto [first_column, last_column] = range(*walk.columns);
  parent.first_row = first_row;
  parent.first_column = first_column;
  parent_rows = last_row - first_row + 1;
  parent.stride = (last_column - first_column + 1) * channels;
  parent.wide_stride = bandParentEntries(walk.width) + kLanes - 1;
}

// Fills `wide`: word j of a row is parent column columns.parent[0] - 8 + j, clamped into the
// copy's columns (whose first is at least columns.parent[0] - 1, word 7 or later).
TESSERA_AVX512 void widenParent(const Walk& walk, uint32_t channels, uint32_t parent_rows,
                                uint32_t* wide, ParentCopy& parent) {
  const auto from = uint32_t(int64_t(parent.first_column) - walk.columns->parent[0] + 8);
  const uint32_t inside = std::min(parent.stride / channels, parent.wide_stride - from);
  for (uint32_t y = 0; y < parent_rows; ++y) {
    uint32_t* to = wide + size_t(y) * parent.wide_stride;
    widenTexels(walk.parent->row(parent.first_row + y) + size_t(parent.first_column) * channels,
                channels, inside, to + from);
    std::fill(to, to + from, to[from]);
    std::fill(to + from + inside, to + parent.wide_stride, to[from + inside - 1]);
  }
  parent.wide = wide;
}

}  // namespace

bool decodeSimd(std::span<const uint8_t> section, const Walk& walk, uint32_t channels,
                Predictor predictor, std::span<const rans::Model* const> context_models,
                bool green_led, std::vector<uint8_t>& padded) {
  const bool has_parent = predictor != Predictor::kRoot;
  const bool corrected = predictor == Predictor::kParentCorrected;
  const bool sides = corrected || predictor == Predictor::kLeastSquares;
  // Predictor 5 with predictor 4's term was removed from coder 7 (decodePtm refuses it).
  if (predictor == Predictor::kLeastSquares && walk.estimates) return false;
  // The scratch after the streams in `padded`, each part 32-byte aligned.
  auto aligned = [](size_t bytes) { return (bytes + 31) / 32 * 32; };
  ParentCopy parent;
  uint32_t parent_rows = 0;
  size_t shortfall_bytes = 0, wide_bytes = 0, table_bytes = 0;
  if (has_parent) {
    copyParent(walk, channels, sides, parent, parent_rows);
    // Predictor 4's shortfall lookups read four bytes from a shortfall's first.
    if (corrected) shortfall_bytes = aligned(size_t(parent_rows) * parent.stride * 2 + 2);
    wide_bytes = aligned(size_t(parent_rows) * parent.wide_stride * 4);
    table_bytes = size_t(bandParentEntries(walk.width)) * kLanes * 4;
  }
  const size_t diagonal_bytes =
      size_t(stepsPerBand(walk.width) + stepOf(1, kLanes - 1)) * kLanes * 4;
  const size_t detail_bytes = corrected ? diagonal_bytes * channels : 0;
  const size_t scratch_bytes =
      shortfall_bytes + diagonal_bytes + wide_bytes + table_bytes * (sides ? 2 : 1) + detail_bytes;
  Streams streams;
  if (!parse(section, channels, 32 + scratch_bytes, padded, streams)) return false;
  Geometry g{walk.texels,
             walk.width,
             walk.height,
             channels,
             has_parent,
             walk.columns,
             walk.rows,
             context_models.data(),
             uint32_t(context_models.size() / channels),
             walk.ls_weights,
             {}};
  if (predictor == Predictor::kLeastSquares)
    sumLeastSquaresWeights(walk.ls_weights, channels, g.ls_sums);
  SlotModels models;
  slotModels(context_models, models);
  uint8_t* scratch = padded.data() + padded.size() - scratch_bytes;
  scratch -= reinterpret_cast<uintptr_t>(scratch) % 32;
  auto* diagonal = reinterpret_cast<uint32_t*>(scratch + shortfall_bytes);
  if (has_parent) {
    auto* wide = diagonal + diagonal_bytes / 4;
    widenParent(walk, channels, parent_rows, wide, parent);
    parent.band_block = wide + wide_bytes / 4;
    if (sides) parent.band_near = parent.band_block + table_bytes / 4;
  }
  auto* shortfall = reinterpret_cast<int16_t*>(scratch);
  if (corrected) blockShortfalls(walk, channels, parent, parent_rows, shortfall);
  const Scratch lanes{&streams,
                      &models,
                      &parent,
                      diagonal,
                      reinterpret_cast<int32_t*>(scratch + scratch_bytes - detail_bytes),
                      shortfall};
  bool ok;
  switch (predictor) {
    case Predictor::kParentNearest:
      ok = decodeWith<LanePredictor::kNearest>(channels, green_led, g, lanes);
      break;
    case Predictor::kParentCorrected:
      ok = decodeWith<LanePredictor::kCorrected>(channels, green_led, g, lanes);
      break;
    case Predictor::kLeastSquares:
      ok = decodeWith<LanePredictor::kLeastSquares>(channels, green_led, g, lanes);
      break;
    default: ok = decodeWith<LanePredictor::kMedian>(channels, green_led, g, lanes);
  }
  return ok && finished(streams, channels);
}

}  // namespace tessera::detail::ptm::lanes::avx512
