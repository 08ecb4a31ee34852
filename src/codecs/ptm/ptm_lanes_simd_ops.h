#pragma once
// The lane decoder's vector operations (ptm_lanes_simd.h, their only user): a band's eight rows
// in the 32-bit lanes of an AVX2 vector, texels held a byte per channel in each lane; and what
// it prepares from the parent before the bands (wide rows, band tables, predictor 4's block
// shortfalls). The translation unit that includes them names the instruction set:
// TESSERA_LANES_ISA, the namespace they go in, and TESSERA_LANES_TARGET, the target attribute
// every function is compiled with (ptm_lanes_avx2.cpp, ptm_lanes_avx512.cpp). Only code that
// checked the processor (simdAvailable(), avx512Available()) may call them.

#include <immintrin.h>

#include <algorithm>
#include <cstdint>
#include <cstring>

#include "ptm/ptm_lanes_internal.h"

#if !defined(TESSERA_LANES_ISA) || !defined(TESSERA_LANES_TARGET)
#error "ptm_lanes_simd_ops.h needs TESSERA_LANES_ISA and TESSERA_LANES_TARGET"
#endif

namespace tessera::detail::ptm::lanes::TESSERA_LANES_ISA {

// What _mm256_i32gather_epi32(base, offsets, kScale) returns, from eight scalar loads: each
// lane's 32 bits at base + offset * kScale (offsets signed, addresses unaligned allowed). On the
// machines the codec study ran on (AMD EPYC, Zen 4) the gather instruction is microcoded: in a
// loop of other vector work it cost 11-12 cycles, the scalar loads about 5 (docs/benchmarks.md,
// "twelfth session"). Every table and plane read this way must hold four bytes at each offset.
template <int kScale>
TESSERA_LANES_TARGET inline __m256i gather32(const void* base, __m256i offsets) {
  const auto* bytes = static_cast<const uint8_t*>(base);
  auto load = [bytes](uint64_t pair, int high) {
    const auto offset = int32_t(uint32_t(pair >> (32 * high)));
    int32_t value;
    std::memcpy(&value, bytes + ptrdiff_t(offset) * kScale, sizeof value);
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

// Sign-extends the low 16 bits of each lane (an int16 read by a 32-bit gather).
TESSERA_LANES_TARGET inline __m256i low16Signed(__m256i v) {
  return _mm256_srai_epi32(_mm256_slli_epi32(v, 16), 16);
}

// LOCO-I's median of each lane's a, b and a + b - c (medPredict).
TESSERA_LANES_TARGET inline __m256i median(__m256i a, __m256i b, __m256i c) {
  const __m256i low = _mm256_min_epi32(a, b), high = _mm256_max_epi32(a, b);
  return _mm256_min_epi32(high, _mm256_max_epi32(low, _mm256_sub_epi32(_mm256_add_epi32(a, b), c)));
}

// Each lane's left, up, up-left and up-right values from its values of the last three steps
// (`back1` the latest): the row above's are lane k - 1's, rotated into lane k, and lane 0's
// come from the band before (`up0`, `up_left0`, `up_right0`, in every lane), with LOCO-I's
// substitutes on the first row and column and the last column (neighbourOffsets).
struct LaneNeighbours {
  __m256i left, up, up_left, up_right;
};
TESSERA_LANES_TARGET inline LaneNeighbours laneNeighbours(__m256i back1, __m256i back2,
                                                          __m256i back3, bool first_band,
                                                          __m256i up0, __m256i up_left0,
                                                          __m256i up_right0, __m256i first_column,
                                                          __m256i at_last_column, __m256i rotate) {
  __m256i u = _mm256_permutevar8x32_epi32(back2, rotate);
  __m256i ul = _mm256_permutevar8x32_epi32(back3, rotate);
  __m256i ur = _mm256_permutevar8x32_epi32(back1, rotate);
  __m256i l = back1;
  if (first_band) {
    // Row 0: every neighbour is the left one.
    u = _mm256_blend_epi32(u, l, 1);
    ul = _mm256_blend_epi32(ul, l, 1);
    ur = _mm256_blend_epi32(ur, l, 1);
  } else {
    u = _mm256_blend_epi32(u, up0, 1);
    ul = _mm256_blend_epi32(ul, up_left0, 1);
    ur = _mm256_blend_epi32(ur, up_right0, 1);
  }
  return {_mm256_blendv_epi8(l, u, first_column), u, _mm256_blendv_epi8(ul, u, first_column),
          _mm256_blendv_epi8(ur, u, at_last_column)};
}

// Channel c of each lane's texel, held a byte per channel.
TESSERA_LANES_TARGET inline __m256i channelOf(__m256i bytes, uint32_t c) {
  return _mm256_and_si256(_mm256_srli_epi32(bytes, int(8 * c)), _mm256_set1_epi32(0xff));
}

// |a - b| of each unsigned byte.
TESSERA_LANES_TARGET inline __m256i absDifference(__m256i a, __m256i b) {
  return _mm256_sub_epi8(_mm256_max_epu8(a, b), _mm256_min_epu8(a, b));
}

// LOCO-I's median of each byte's a, b and a + b - c (medPredict) without leaving bytes: with
// low = min(a, b) and high = max(a, b) it is low + min(max(high - c, 0), high - low), since
// a + b - c = low + (high - c) lies between low and high exactly when c does.
TESSERA_LANES_TARGET inline __m256i medianBytes(__m256i a, __m256i b, __m256i c) {
  const __m256i low = _mm256_min_epu8(a, b), high = _mm256_max_epu8(a, b);
  return _mm256_add_epi8(low,
                         _mm256_min_epu8(_mm256_subs_epu8(high, c), _mm256_sub_epi8(high, low)));
}

// Where a band's lanes find their blocks' parent texels in the decoder's copy of the parent
// (blockAt), for predictor 4's block shortfalls, which lie in the copy's layout.
struct ParentPlaces {
  __m256i rows;  ///< each lane's parent row's offset in the copy
  __m256i two_lane, last_column;
  uint32_t column_offset;  ///< see decodeAvx2's column_offset
  uint32_t first_column;   ///< the copy's first parent column
};

// Each lane's block's parent texel at step t: its place in the copy (idle lanes' columns kept
// in the tile).
template <uint32_t kCh>
TESSERA_LANES_TARGET inline __m256i blockAt(uint32_t t, const ParentPlaces& p) {
  const __m256i zero = _mm256_setzero_si256();
  const __m256i column_in = _mm256_min_epi32(
      _mm256_max_epi32(_mm256_sub_epi32(_mm256_set1_epi32(int(t)), p.two_lane), zero),
      p.last_column);
  const __m256i parent_column =
      _mm256_srli_epi32(_mm256_add_epi32(column_in, _mm256_set1_epi32(int(p.column_offset))), 1);
  return _mm256_add_epi32(
      p.rows,
      _mm256_mullo_epi32(_mm256_sub_epi32(parent_column, _mm256_set1_epi32(int(p.first_column))),
                         _mm256_set1_epi32(int(kCh))));
}

// A band's parent texels by step, so that a step reads its lanes' with one aligned load
// instead of a gather: lane k of `entries` words' entry e is word e + 7 - k of the wide copy's
// row `wide_rows[k]` (ParentCopy::wide), which is lane k's parent texel at step t where
// e = bandParentEntry(t, column_offset) (and at the texel's block's side, e -+ 1). Eight
// entries at a time: each lane's eight words, skewed by one per lane, transposed.
TESSERA_LANES_TARGET inline void skewedParents(const uint32_t* wide, uint32_t wide_stride,
                                               const int32_t* wide_rows, uint32_t entries,
                                               uint32_t* out) {
  for (uint32_t e0 = 0; e0 < entries; e0 += 8) {
    __m256i r[8];
    for (uint32_t k = 0; k < 8; ++k)
      r[k] = _mm256_loadu_si256(
          reinterpret_cast<const __m256i*>(wide + size_t(wide_rows[k]) * wide_stride + e0 + 7 - k));
    __m256i pairs[8], quads[8];
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

// `count` texels of `channels` bytes as 32-bit words, the bytes past a texel's cleared (the
// wide copy's rows, ParentCopy::wide): four texels per instruction, reading no byte past the
// last texel's.
TESSERA_LANES_TARGET inline void widenTexels(const uint8_t* texels, uint32_t channels,
                                             uint32_t count, uint32_t* out) {
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

// The 16 bytes of four words from `words` as 16-bit lanes (four texels of a wide row, every
// channel).
TESSERA_LANES_TARGET inline __m256i bytesAs16(const uint32_t* words) {
  return _mm256_cvtepu8_epi16(_mm_loadu_si128(reinterpret_cast<const __m128i*>(words)));
}

// Entry `entry` of a band's parent table (skewedParents).
TESSERA_LANES_TARGET inline __m256i bandParents(const uint32_t* table, uint32_t entry) {
  return _mm256_load_si256(reinterpret_cast<const __m256i*>(table + size_t(entry) * 8));
}

// Predictor 4's shortfall of each block wholly in the tile, per channel, at its parent texel's
// place in `parent`'s copy: 16 (4P + 1.5) less its four texels' upsampled values (0 elsewhere).
// From the parent's wide rows rather than the walk's upsampled plane, which this decoder does
// without: with each child's W = 9 P + 3 Ph + 3 Pv + Pd + 6 (upsampleParent), a block whose
// children's side texels are Pl and Pr and whose rows' are Pu and Pd sums to
// 36 P + 6 (Pl + Pr + Pu + Pd) + (the four diagonal texels) + 24, so its shortfall is
// 28 P - 6 (Pl + Pr + Pu + Pd) - (Pul + Pur + Pdl + Pdr), four blocks and every channel at once
// in 16-bit lanes. mapAxis makes the side texels P's neighbours, clamped to the parent, which
// is what the wide rows' padding holds.
TESSERA_LANES_TARGET inline void blockShortfalls(const Walk& walk, uint32_t channels,
                                                 const ParentCopy& parent, uint32_t parent_rows,
                                                 int16_t* shortfall) {
  std::fill_n(shortfall, size_t(parent_rows) * parent.stride, int16_t(0));
  const AxisMap& columns = *walk.columns;
  const AxisMap& rows = *walk.rows;
  // The blocks wholly in the tile have first children from column `first` to `last`, every
  // other column.
  uint32_t first = walk.width, last = 0;
  for (uint32_t x = 0; x + 1 < walk.width; ++x)
    if (columns.full[x] != 0 && columns.second[x] == 0) {
      first = std::min(first, x);
      last = x;
    }
  if (first > last) return;
  const uint32_t first_block = columns.parent[first], blocks = (last - first) / 2 + 1;
  // Word j of a wide row is parent column columns.parent[0] - 8 + j.
  const uint32_t at = first_block - columns.parent[0] + 8;
  const __m256i six = _mm256_set1_epi16(6), twenty_eight = _mm256_set1_epi16(28);
  for (uint32_t y = 0; y + 1 < walk.height; ++y) {
    if (rows.full[y] == 0 || rows.second[y] != 0) continue;
    const uint32_t* middle =
        parent.wide + size_t(rows.parent[y] - parent.first_row) * parent.wide_stride + at;
    const uint32_t* above =
        parent.wide + size_t(rows.neighbour[y] - parent.first_row) * parent.wide_stride + at;
    const uint32_t* below =
        parent.wide + size_t(rows.neighbour[y + 1] - parent.first_row) * parent.wide_stride + at;
    int16_t* out = shortfall + size_t(rows.parent[y] - parent.first_row) * parent.stride +
                   size_t(first_block - parent.first_column) * channels;
    for (uint32_t i = 0; i < blocks; i += 4) {
      const __m256i p = bytesAs16(middle + i), pl = bytesAs16(middle + i - 1),
                    pr = bytesAs16(middle + i + 1);
      const __m256i pu = bytesAs16(above + i), pul = bytesAs16(above + i - 1),
                    pur = bytesAs16(above + i + 1);
      const __m256i pd = bytesAs16(below + i), pdl = bytesAs16(below + i - 1),
                    pdr = bytesAs16(below + i + 1);
      const __m256i sides = _mm256_add_epi16(_mm256_add_epi16(pl, pr), _mm256_add_epi16(pu, pd));
      const __m256i corners =
          _mm256_add_epi16(_mm256_add_epi16(pul, pur), _mm256_add_epi16(pdl, pdr));
      const __m256i g = _mm256_sub_epi16(
          _mm256_sub_epi16(_mm256_mullo_epi16(p, twenty_eight), _mm256_mullo_epi16(sides, six)),
          corners);
      alignas(32) int16_t g4[16];
      _mm256_store_si256(reinterpret_cast<__m256i*>(g4), g);
      for (uint32_t b = 0; b < 4 && i + b < blocks; ++b)
        std::memcpy(out + size_t(i + b) * channels, g4 + 4 * b, channels * sizeof(int16_t));
    }
  }
}

// Channel c of each lane's texels `low` and `high` (a byte per channel) as the low and high
// 16 bits of the lane, by the byte shuffles `low_mask` and `high_mask` (decodeAvx2 builds them
// per channel).
TESSERA_LANES_TARGET inline __m256i channelPair(__m256i low, __m256i high, __m256i low_mask,
                                                __m256i high_mask) {
  return _mm256_or_si256(_mm256_shuffle_epi8(low, low_mask), _mm256_shuffle_epi8(high, high_mask));
}

// Predictor 5's sum without its ninth term (leastSquaresPredictFactored) for channel c, over 16
// and without the rounding's low bits: Σ w v - m Σw + 64, which is the factored sum's
// (16 (Σ w v - m Σw) + 1024) / 16. Each multiply-add takes two terms: `pairs` holds each
// lane's weights of (L, U), (UL, UR), (P, Ph), (Pv, Pd) and (m, 1), the last -Σw and 64, as
// 16-bit pairs. `low_mask` and `high_mask` pick channel c (channelPair).
TESSERA_LANES_TARGET inline __m256i leastSquaresSixteenths(
    const __m256i* pairs, __m256i low_mask, __m256i high_mask, __m256i medians, __m256i left,
    __m256i up, __m256i up_left, __m256i up_right, __m256i parents, __m256i side_parents,
    __m256i near_parents, __m256i diagonal_parents) {
  const __m256i median_and_one =
      _mm256_or_si256(_mm256_shuffle_epi8(medians, low_mask), _mm256_set1_epi32(1 << 16));
  const __m256i neighbours = _mm256_add_epi32(
      _mm256_madd_epi16(channelPair(left, up, low_mask, high_mask), pairs[0]),
      _mm256_madd_epi16(channelPair(up_left, up_right, low_mask, high_mask), pairs[1]));
  const __m256i parent_terms = _mm256_add_epi32(
      _mm256_madd_epi16(channelPair(parents, side_parents, low_mask, high_mask), pairs[2]),
      _mm256_madd_epi16(channelPair(near_parents, diagonal_parents, low_mask, high_mask),
                        pairs[3]));
  return _mm256_add_epi32(_mm256_add_epi32(neighbours, parent_terms),
                          _mm256_madd_epi16(median_and_one, pairs[4]));
}

// leastSquaresSixteenths' pairs of terms: four of the eight terms' weights, and the weights' sum.
inline constexpr uint32_t kLsPairs = 5;

}  // namespace tessera::detail::ptm::lanes::TESSERA_LANES_ISA
