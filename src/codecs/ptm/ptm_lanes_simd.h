// ptm's lane coder, the SIMD decoder (ptm_lanes_internal.h): the eight rows of a band in the
// lanes of an AVX2 vector. Not a header of declarations: ptm_lanes_avx2.cpp and
// ptm_lanes_avx512.cpp each include it once, after naming the instruction set it is compiled
// for (TESSERA_LANES_ISA, TESSERA_LANES_TARGET; ptm_lanes_simd_ops.h).
#include <immintrin.h>

#include <algorithm>
#include <cstddef>
#include <cstring>
#include <memory>

#include "ptm/ptm_lanes_internal.h"
#include "ptm/ptm_lanes_simd_ops.h"

namespace tessera::detail::ptm::lanes::TESSERA_LANES_ISA {

namespace {

// For each mask of lanes that read, where each lane finds its item among those read: lane i
// takes item (number of reading lanes below i).
struct Compaction {
  alignas(32) int32_t index[256][kLanes];
  Compaction() {
    for (uint32_t mask = 0; mask < 256; ++mask) {
      int32_t n = 0;
      for (uint32_t i = 0; i < kLanes; ++i) index[mask][i] = (mask >> i & 1) != 0 ? n++ : 0;
    }
  }
};
const Compaction kCompaction;

// Which predictor a lane decoder runs: 0 and 3 (the median), 1, 4 or 5.
enum class LanePredictor : uint8_t {
  kMedian,
  kNearest,
  kCorrected,
  kLeastSquares,
  kLeastSquaresPlain
};

// kNearest: predictor 1, the block's parent texel.
// kCorrected: predictor 4, which also reads the parent texels beside each block's (`parent`
// then covers them), from which it computes the walk's upsampled parent, and `shortfall`, the
// parent-sized plane of eq. 3's block sum less its texels' upsampled values (decode()).
//
// kLeastSquares: predictor 5, predictor 4's estimate and more.
//
// kGreenLed: red's and blue's contexts follow green's residual (leadByGreen; 3 and 4 channels).
template <uint32_t kCh, LanePredictor kPredictor, bool kGreenLed>
TESSERA_LANES_TARGET bool decodeAvx2(const Geometry& g, Streams& s, const SlotModels& models,
                                     const ParentCopy& parent, uint32_t* diagonal,
                                     int32_t* detail_diagonal, const int16_t* shortfall) {
  constexpr bool kNearest = kPredictor == LanePredictor::kNearest;
  // Predictor 5's ninth term is predictor 4's estimate.
  constexpr bool kCorrected =
      kPredictor == LanePredictor::kCorrected || kPredictor == LanePredictor::kLeastSquares;
  constexpr bool kLeastSquares =
      kPredictor == LanePredictor::kLeastSquares || kPredictor == LanePredictor::kLeastSquaresPlain;
  // Predictors 1 and 5 read the block's parent texel at every step, the others for derived
  // texels only.
  constexpr bool kEveryStep = kNearest || kLeastSquares;
  static_assert(kLanes == 8, "a band's rows are the eight 32-bit lanes of one AVX2 vector");
  // Locals, not the structures' fields: every vector store may alias those, and the compiler
  // would reload them at every step.
  const uint32_t width = g.width, height = g.height;
  const bool has_parent = g.has_parent;
  const uint8_t* words_at[kCh];
  const uint8_t* escapes_at[kCh];
  for (uint32_t c = 0; c < kCh; ++c) {
    words_at[c] = s.words[c];
    escapes_at[c] = s.escapes[c];
  }
  const size_t stride = size_t(width) * kCh;
  const uint32_t steps = stepsPerBand(width);
  // Words per channel of `detail_diagonal`, as of `diagonal`.
  [[maybe_unused]] const size_t diagonal_words = size_t(steps + stepOf(1, kLanes - 1)) * kLanes;
  const int* slot_tables = reinterpret_cast<const int*>(models.tables);
  const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  const __m256i two_lane = _mm256_slli_epi32(lane, 1);
  // Rotates lane k - 1's value into lane k; lane 0's is replaced after.
  const __m256i rotate = _mm256_setr_epi32(7, 0, 1, 2, 3, 4, 5, 6);
  const __m256i slot_mask = _mm256_set1_epi32(int(kScale - 1));
  [[maybe_unused]] const __m256i low16 = _mm256_set1_epi32(0xffff);
  [[maybe_unused]] const __m256i above16 = _mm256_set1_epi32(0x10000);
  const __m256i byte_mask = _mm256_set1_epi32(0xff);
  const __m256i symbol_mask = _mm256_set1_epi32((1 << kSymbolBits) - 1);
  const __m256i one = _mm256_set1_epi32(1);
  const __m256i escape = _mm256_set1_epi32(int(kEscape));
  const __m256i zero = _mm256_setzero_si256();
  const __m256i three = _mm256_set1_epi32(3);
  // A texel's kCh bytes in each lane.
  const __m256i ones8 = _mm256_set1_epi8(1), ones16 = _mm256_set1_epi16(1);
  // Adds each texel's byte 1 (green) to its bytes 0 and 2.
  const __m256i green_to_red_and_blue =
      _mm256_setr_epi8(1, -1, 1, -1, 5, -1, 5, -1, 9, -1, 9, -1, 13, -1, 13, -1, 1, -1, 1, -1, 5,
                       -1, 5, -1, 9, -1, 9, -1, 13, -1, 13, -1);
  const __m256i last_column = _mm256_set1_epi32(int(width) - 1);
  // The copy into rows: eight texels of a row lie kLanes words apart; within each half of the
  // vector the shuffle packs four texels' kCh bytes to the front, and the permute joins the
  // halves.
  const __m256i octet_at = _mm256_mullo_epi32(lane, _mm256_set1_epi32(int(kLanes)));
  alignas(32) int8_t pack_bytes[32];
  for (uint32_t i = 0; i < 16; ++i) {
    const int8_t byte = i < 4 * kCh ? int8_t(i / kCh * 4 + i % kCh) : int8_t(-1);
    pack_bytes[i] = byte;
    pack_bytes[16 + i] = byte;
  }
  const __m256i pack = _mm256_load_si256(reinterpret_cast<const __m256i*>(pack_bytes));
  alignas(32) int32_t halves[8];
  for (uint32_t i = 0; i < 8; ++i) halves[i] = int32_t(i < kCh ? i : i < 2 * kCh ? i - kCh + 4 : 7);
  const __m256i pack_halves = _mm256_load_si256(reinterpret_cast<const __m256i*>(halves));
  // The class bounds from memory at every use: built from the tile's channel count at run time,
  // so that the compiler cannot rebuild them from immediates at every step, as it did for want
  // of registers.
  alignas(32) int32_t bounds[kActivityClasses - 1][kLanes];
  for (uint32_t i = 0; i < kActivityClasses - 1; ++i)
    std::fill_n(bounds[i], kLanes, kActivityBounds[i] * int(g.channels) - 1);
  // Each channel's model offsets by context group (the block positions 0-3, then remainders),
  // eight activity classes each: a lane picks its model with a permute, not a gather.
  constexpr uint32_t kGroups = kParentContexts / kActivityClasses;
  __m256i group_models[kCh][kGroups];
  for (uint32_t c = 0; c < kCh; ++c)
    for (uint32_t group = 0; group < kGroups; ++group)
      group_models[c][group] =
          group * kActivityClasses < g.contexts
              ? _mm256_loadu_si256(reinterpret_cast<const __m256i*>(
                    models.offsets + c * g.contexts + group * kActivityClasses))
              : zero;
  // Green-led contexts: per position group, green's model's frequency of symbol 0, and red's
  // and blue's model offsets by class after a zero green residual and after any other
  // (greenLedClass). The remainders' group is not led.
  static_assert(!kGreenLed || kCh >= 3, "green leads red and blue only");
  [[maybe_unused]] __m256i green_zero_freqs[kGroups - 1];
  [[maybe_unused]] __m256i led_models[kGreenLed ? kCh : 1][2][kGroups - 1];
  if constexpr (kGreenLed)
    for (uint32_t group = 0; group + 1 < kGroups; ++group) {
      alignas(32) int32_t freqs[kLanes] = {}, after[2][kCh][kLanes] = {};
      if (group * kActivityClasses < g.contexts)
        for (uint32_t k = 0; k < kActivityClasses; ++k) {
          const uint32_t context = group * kActivityClasses + k;
          freqs[k] = g.models[kGreenChannel * g.contexts + context]->freq[0];
          for (uint32_t zero_green = 0; zero_green < 2; ++zero_green)
            for (uint32_t c = 0; c < kCh; ++c)
              after[zero_green][c][k] = models.offsets[c * g.contexts + group * kActivityClasses +
                                                       greenLedClass(k, zero_green != 0)];
        }
      green_zero_freqs[group] = _mm256_load_si256(reinterpret_cast<const __m256i*>(freqs));
      for (uint32_t zero_green = 0; zero_green < 2; ++zero_green)
        for (uint32_t c = 0; c < kCh; ++c)
          led_models[c][zero_green][group] =
              _mm256_load_si256(reinterpret_cast<const __m256i*>(after[zero_green][c]));
    }
  // The columns' parent texels: child column x lies in parent column (x + offset) / 2, the
  // second child of its block when x + offset is odd (mapAxis), so every lane of a step, whose
  // columns differ by even numbers, is a first child or every lane a second.
  const uint32_t column_offset = has_parent ? 2 * g.columns->parent[0] + g.columns->second[0] : 0;
  // Predictor 4 pulls a texel only where its block lies wholly in the tile: a first column that
  // is a block's second child, or a last column that is a first, never.
  const bool first_column_partial = kCorrected && g.columns->full.front() == 0;
  const bool last_column_partial = kCorrected && g.columns->full.back() == 0;
  // Predictor 4's W in two multiply-adds of channel pairs: (P, Ph) by (9, 3), (Pv, Pd) by (3, 1).
  [[maybe_unused]] const __m256i nine_three = _mm256_set1_epi32(9 | 3 << 16);
  [[maybe_unused]] const __m256i three_one = _mm256_set1_epi32(3 | 1 << 16);
  [[maybe_unused]] const __m256i six = _mm256_set1_epi32(6);
  const int* shortfalls = reinterpret_cast<const int*>(shortfall);
  const __m256 twelve = _mm256_set1_ps(12.0f);
  // Predictor 5: the byte shuffles that put channel c of each lane in its low and its high 16
  // bits (leastSquaresSixteenths).
  [[maybe_unused]] __m256i low_masks[kCh], high_masks[kCh];
  for (uint32_t c = 0; c < kCh; ++c) {
    alignas(32) int8_t low[32], high[32];
    for (uint32_t i = 0; i < 32; ++i) {
      const auto byte = int8_t(i / 4 % 4 * 4 + c);
      low[i] = i % 4 == 0 ? byte : int8_t(-1);
      high[i] = i % 4 == 2 ? byte : int8_t(-1);
    }
    low_masks[c] = _mm256_load_si256(reinterpret_cast<const __m256i*>(low));
    high_masks[c] = _mm256_load_si256(reinterpret_cast<const __m256i*>(high));
  }
  const __m256i eight = _mm256_set1_epi32(8);
  __m256i state[kCh];
  for (uint32_t c = 0; c < kCh; ++c)
    state[c] = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(s.states[c]));
  __m256i failed = zero;
  for (uint32_t y0 = 0; y0 < height; y0 += kLanes) {
    const uint32_t rows = std::min(kLanes, height - y0);
    const __m256i row_in = _mm256_cmpgt_epi32(_mm256_set1_epi32(int(rows)), lane);
    // Per lane: its row's parent row offset, second-row and derived-row flags, and (predictor
    // 4) whether the row's blocks lie in the tile.
    alignas(32) int32_t parent_row_at[kLanes] = {}, row_second[kLanes] = {},
                        row_derived[kLanes] = {}, row_full[kLanes] = {};
    if (has_parent)
      for (uint32_t k = 0; k < rows; ++k) {
        parent_row_at[k] = int32_t((g.rows->parent[y0 + k] - parent.first_row) * parent.stride);
        row_second[k] = g.rows->second[y0 + k] != 0 ? -1 : 0;
        row_derived[k] = g.rows->derived[y0 + k] != 0 ? -1 : 0;
        row_full[k] = g.rows->full[y0 + k] != 0 ? -1 : 0;
      }
    const __m256i parent_rows = _mm256_load_si256(reinterpret_cast<const __m256i*>(parent_row_at));
    const __m256i second_row = _mm256_load_si256(reinterpret_cast<const __m256i*>(row_second));
#ifdef TESSERA_LANES_AVX512
    // The second table's bit in a two-table permute's index, in the lanes of second rows.
    const __m256i second_row_table = _mm256_and_si256(second_row, _mm256_set1_epi32(8));
#endif
    const __m256i derived_row = _mm256_load_si256(reinterpret_cast<const __m256i*>(row_derived));
    const __m256i full_row = _mm256_load_si256(reinterpret_cast<const __m256i*>(row_full));
    [[maybe_unused]] const ParentPlaces places{parent_rows, two_lane, last_column, column_offset,
                                               parent.first_column};
    // Each step's parent texels for the lanes, from the wide copy's rows: the blocks' (lanes
    // past the tile's last row read row 0), and for predictor 5 the rows beside them.
    if (has_parent) {
      alignas(32) int32_t wide_rows[kLanes] = {}, wide_near_rows[kLanes] = {};
      for (uint32_t k = 0; k < rows; ++k) {
        wide_rows[k] = int32_t(g.rows->parent[y0 + k] - parent.first_row);
        if constexpr (kLeastSquares || kCorrected)
          wide_near_rows[k] = int32_t(g.rows->neighbour[y0 + k] - parent.first_row);
      }
      const uint32_t entries = bandParentEntries(width);
      skewedParents(parent.wide, parent.wide_stride, wide_rows, entries, parent.band_block);
      if constexpr (kLeastSquares || kCorrected)
        skewedParents(parent.wide, parent.wide_stride, wide_near_rows, entries, parent.band_near);
    }
    const bool first_band = y0 == 0;
    // Predictor 5: per step parity (second column or not) and channel, each lane's weights for
    // its block position as leastSquaresSixteenths' pairs, and the weight of predictor 4's
    // estimate.
    [[maybe_unused]] __m256i ls_pairs[kLeastSquares ? 2 : 1][kCh][kLsPairs];
    [[maybe_unused]] __m256i ls_estimate_weights[kLeastSquares ? 2 : 1][kCh];
    if constexpr (kLeastSquares)
      for (uint32_t column = 0; column < 2; ++column)
        for (uint32_t c = 0; c < kCh; ++c) {
          const int8_t* first = g.ls_weights + (column * kCh + c) * kLsTerms;
          const int8_t* second = g.ls_weights + ((2 + column) * kCh + c) * kLsTerms;
          auto pair = [](int low, int high) { return int(uint16_t(low)) | high << 16; };
          for (uint32_t k = 0; k < kLsPairs; ++k) {
            const bool sum = k == kLsPairs - 1;
            ls_pairs[column][c][k] = _mm256_blendv_epi8(
                _mm256_set1_epi32(sum ? pair(-g.ls_weight_sums[column][c], 64)
                                      : pair(first[2 * k], first[2 * k + 1])),
                _mm256_set1_epi32(sum ? pair(-g.ls_weight_sums[2 + column][c], 64)
                                      : pair(second[2 * k], second[2 * k + 1])),
                second_row);
          }
          ls_estimate_weights[column][c] =
              _mm256_blendv_epi8(_mm256_set1_epi32(first[kLsTerms - 1]),
                                 _mm256_set1_epi32(second[kLsTerms - 1]), second_row);
        }
    // Each lane's texels of the last three steps, channel c in byte c: left, and (rotated) the
    // row above's. Predictor 4 keeps their departures from the upsampled parent likewise, per
    // channel.
    __m256i back1 = zero, back2 = zero, back3 = zero;
    __m256i detail1[kCh], detail2[kCh], detail3[kCh];
    for (uint32_t c = 0; c < kCh; ++c) detail1[c] = detail2[c] = detail3[c] = zero;
    [[maybe_unused]] __m256i previous_shortfalls[(kCh + 1) / 2] = {};
    for (uint32_t t = 0; t < steps; ++t) {
      const __m256i xs = _mm256_sub_epi32(_mm256_set1_epi32(int(t)), two_lane);
      const __m256i active = _mm256_and_si256(
          _mm256_andnot_si256(_mm256_cmpgt_epi32(zero, xs),
                              _mm256_cmpgt_epi32(_mm256_set1_epi32(int(width)), xs)),
          row_in);
      const __m256i first_column = _mm256_cmpeq_epi32(xs, zero);
      const __m256i at_last_column = _mm256_cmpeq_epi32(xs, last_column);
      // Lane 0's row above is the last lane's of the band before, whose steps still lie
      // ahead of this one's in `diagonal` (row 0 takes substitutes instead).
      const size_t above_at = size_t(stepOf(t, kLanes - 1)) * kLanes + (kLanes - 1);
      const uint32_t* above = diagonal + above_at;
      // Predictor 4: its departures likewise, from `detail_diagonal`, per channel (idle lanes'
      // and substituted places' are any values).
      [[maybe_unused]] __m256i up0_detail[kCh], up_left0_detail[kCh], up_right0_detail[kCh];
      if constexpr (kCorrected)
        for (uint32_t c = 0; c < kCh; ++c) {
          const int32_t* above_detail = detail_diagonal + c * diagonal_words + above_at;
          up0_detail[c] = first_band ? zero : _mm256_set1_epi32(above_detail[0]);
          up_left0_detail[c] =
              first_band ? zero : _mm256_set1_epi32(above_detail[-ptrdiff_t(kLanes)]);
          up_right0_detail[c] = first_band ? zero : _mm256_set1_epi32(above_detail[kLanes]);
        }
      // Predictor 4: where the block sum pulls.
      [[maybe_unused]] __m256i pulled = zero;
      if constexpr (kCorrected) {
        __m256i column_partial = zero;
        if (first_column_partial) column_partial = first_column;
        if (last_column_partial) column_partial = _mm256_or_si256(column_partial, at_last_column);
        pulled = _mm256_andnot_si256(column_partial, _mm256_and_si256(full_row, active));
      }
      // The neighbours of all channels at once, a byte each: the activity sums their
      // differences with byte instructions and the median is taken bytewise.
      const auto [left, up, up_left, up_right] = laneNeighbours(
          back1, back2, back3, first_band, _mm256_set1_epi32(int(above[0])),
          _mm256_set1_epi32(int(above[-ptrdiff_t(kLanes)])), _mm256_set1_epi32(int(above[kLanes])),
          first_column, at_last_column, rotate);
      const __m256i activity = _mm256_madd_epi16(
          _mm256_add_epi16(
              _mm256_add_epi16(_mm256_maddubs_epi16(absDifference(left, up_left), ones8),
                               _mm256_maddubs_epi16(absDifference(up, up_left), ones8)),
              _mm256_maddubs_epi16(absDifference(up_right, up), ones8)),
          ones16);
      const __m256i medians = medianBytes(left, up, up_left);
      __m256i activity_class = zero;
      for (const auto& bound : bounds)
        activity_class = _mm256_sub_epi32(
            activity_class,
            _mm256_cmpgt_epi32(activity,
                               _mm256_load_si256(reinterpret_cast<const __m256i*>(bound))));
      [[maybe_unused]] __m256i predicted[kCh];
      [[maybe_unused]] __m256i upsampled_value[kCh];
      [[maybe_unused]] __m256i estimate_terms[kCh];
      // Each lane's model group: its block position, or the remainders for a derived texel.
      const uint32_t second_column = has_parent ? (t + column_offset) & 1 : 0;
      __m256i derived = zero;
      if (has_parent && second_column != 0)
        derived =
            _mm256_and_si256(_mm256_and_si256(derived_row, active), _mm256_cmpgt_epi32(xs, zero));
      const int derived_mask = _mm256_movemask_ps(_mm256_castsi256_ps(derived));
      // The blocks' parent texels P, and for predictor 5 Ph, Pv and Pd beside them (mapAxis's
      // neighbours, clamped to the parent), from the band's tables (skewedParents).
      const uint32_t parent_entry = bandParentEntry(t, column_offset);
      const uint32_t side_entry = second_column != 0 ? parent_entry + 1 : parent_entry - 1;
      __m256i block_parents = zero;
      if (kEveryStep || kCorrected || derived_mask != 0)
        block_parents = bandParents(parent.band_block, parent_entry);
      [[maybe_unused]] __m256i side_parents = zero, near_parents = zero, diagonal_parents = zero;
      if constexpr (kLeastSquares || kCorrected) {
        side_parents = bandParents(parent.band_block, side_entry);
        near_parents = bandParents(parent.band_near, parent_entry);
        diagonal_parents = bandParents(parent.band_near, side_entry);
      }
      [[maybe_unused]] __m256i parent_at = zero;
      if constexpr (kCorrected) parent_at = blockAt<kCh>(t, places);
      if constexpr (kCorrected) {
        // Predictor 4 (ptm_walk.h, parentCorrectedEstimate), with eq. 3's pull written from
        // the block's shortfall G = 16 (4P + 1.5) - (Wa + Wb + Wc + Wd): a's pull is
        // (G - 4δ) >> 3, b's (G - D(a) - 3δ) / 12 and c's (G - D(a) - D(b) - 2δ) >> 2, the same
        // integers as the walk's, since D(t) = 16 t - W(t).
        // W, the upsampled parent (upsampleParent, ptm_walk.cpp): 9 P + 3 Ph + 3 Pv + Pd + 6, in
        // two multiply-adds of channel pairs.
        for (uint32_t c = 0; c < kCh; ++c)
          upsampled_value[c] = _mm256_add_epi32(
              _mm256_add_epi32(_mm256_madd_epi16(channelPair(block_parents, side_parents,
                                                             low_masks[c], high_masks[c]),
                                                 nine_three),
                               _mm256_madd_epi16(channelPair(near_parents, diagonal_parents,
                                                             low_masks[c], high_masks[c]),
                                                 three_one)),
              six);
        // Two channels' int16 shortfalls per 32-bit gather (with an odd channel count the last
        // gather's high half is the next texel's, or the planes' slack). A block's second
        // column has its first's shortfall (at column 0 too: the step before read column 0's).
        __m256i block_shortfalls[kCh];
        const bool same_block = second_column != 0 && t > 0;
        for (uint32_t c = 0; c < kCh; c += 2) {
          const __m256i gs =
              same_block
                  ? previous_shortfalls[c / 2]
                  : gather32<2>(shortfalls, _mm256_add_epi32(parent_at, _mm256_set1_epi32(int(c))));
          previous_shortfalls[c / 2] = gs;
          block_shortfalls[c] = low16Signed(gs);
          if (c + 1 < kCh) block_shortfalls[c + 1] = _mm256_srai_epi32(gs, 16);
        }
        for (uint32_t c = 0; c < kCh; ++c) {
          const __m256i w = upsampled_value[c];
          const __m256i block_shortfall = block_shortfalls[c];
          const auto [dl, du, dul, dur] = laneNeighbours(
              detail1[c], detail2[c], detail3[c], first_band, up0_detail[c], up_left0_detail[c],
              up_right0_detail[c], first_column, at_last_column, rotate);
          const __m256i departure = median(dl, du, dul);
          __m256i pull;
          if (second_column == 0) {
            const __m256i first = _mm256_srai_epi32(
                _mm256_sub_epi32(block_shortfall, _mm256_slli_epi32(departure, 2)), 3);
            const __m256i second = _mm256_srai_epi32(
                _mm256_sub_epi32(_mm256_sub_epi32(_mm256_sub_epi32(block_shortfall, du), dur),
                                 _mm256_slli_epi32(departure, 1)),
                2);
            pull = _mm256_and_si256(_mm256_blendv_epi8(first, second, second_row), pulled);
          } else {
            // C's division towards zero, exact in single precision: |n| <= 16344 + 4086 + 3 * 4086.
            const __m256i n =
                _mm256_sub_epi32(_mm256_sub_epi32(block_shortfall, dl),
                                 _mm256_add_epi32(_mm256_slli_epi32(departure, 1), departure));
            pull =
                _mm256_and_si256(_mm256_cvttps_epi32(_mm256_div_ps(_mm256_cvtepi32_ps(n), twelve)),
                                 _mm256_andnot_si256(second_row, pulled));
          }
          const __m256i estimate = _mm256_add_epi32(_mm256_add_epi32(w, departure), pull);
          if constexpr (kLeastSquares) {
            // Predictor 5's ninth term, added to its sum below.
            estimate_terms[c] = _mm256_mullo_epi32(ls_estimate_weights[second_column][c], estimate);
          } else {
            predicted[c] = _mm256_min_epi32(
                byte_mask,
                _mm256_max_epi32(zero, _mm256_srai_epi32(_mm256_add_epi32(estimate, eight), 4)));
          }
        }
      }
      if constexpr (kLeastSquares)
        for (uint32_t c = 0; c < kCh; ++c) {
          // Predictor 5 (leastSquaresPredictFactored): the factored sum over 16, shifted by 4
          // bits less; with predictor 4's estimate, whose term is no multiple of 16, the whole
          // sum.
          const __m256i sixteenths = leastSquaresSixteenths(
              ls_pairs[second_column][c], low_masks[c], high_masks[c], medians, left, up, up_left,
              up_right, block_parents, side_parents, near_parents, diagonal_parents);
          __m256i correction;
          if constexpr (kCorrected)
            correction = _mm256_srai_epi32(
                _mm256_add_epi32(_mm256_slli_epi32(sixteenths, 4), estimate_terms[c]),
                kLsProductShift);
          else
            correction = _mm256_srai_epi32(sixteenths, kLsProductShift - 4);
          predicted[c] = _mm256_min_epi32(
              byte_mask,
              _mm256_max_epi32(zero, _mm256_add_epi32(channelOf(medians, c), correction)));
        }
      __m256i symbols[kCh];
#ifdef TESSERA_LANES_AVX512
      const auto active_lanes = __mmask8(_mm256_movemask_ps(_mm256_castsi256_ps(active)));
#endif
      // A coded texel's value of its position group's `groups` for its class: the block
      // position picks the group, and the class the lane.
      auto byClass = [&](const __m256i* groups) TESSERA_LANES_TARGET {
#ifdef TESSERA_LANES_AVX512
        // One permute of two tables: the class picks the entry, the row's parity the table.
        return has_parent
                   ? _mm256_permutex2var_epi32(groups[second_column],
                                               _mm256_or_si256(activity_class, second_row_table),
                                               groups[2 + second_column])
                   : _mm256_permutevar8x32_epi32(groups[second_column], activity_class);
#else
        const __m256i first = _mm256_permutevar8x32_epi32(groups[second_column], activity_class);
        if (!has_parent) return first;
        return _mm256_blendv_epi8(
            first, _mm256_permutevar8x32_epi32(groups[2 + second_column], activity_class),
            second_row);
#endif
      };
      // Green-led contexts: green's symbol is 0 where its slot lies below its model's frequency
      // of 0, whose slots come first; so red's and blue's models are known before green's
      // lookup, and their lookups wait for no other.
      [[maybe_unused]] __m256i green_zero = zero;
      if constexpr (kGreenLed)
        green_zero = _mm256_cmpgt_epi32(byClass(green_zero_freqs),
                                        _mm256_and_si256(state[kGreenChannel], slot_mask));
      for (uint32_t c = 0; c < kCh; ++c) {
        __m256i model;
        if (kGreenLed && followsGreen(c))
          model =
              _mm256_blendv_epi8(byClass(led_models[c][0]), byClass(led_models[c][1]), green_zero);
        else
          model = byClass(group_models[c]);
        if (derived_mask != 0) {
#ifdef TESSERA_LANES_AVX512
          model = _mm256_mask_permutexvar_epi32(model, __mmask8(derived_mask), activity_class,
                                                group_models[c][kGroups - 1]);
#else
          model = _mm256_blendv_epi8(
              model, _mm256_permutevar8x32_epi32(group_models[c][kGroups - 1], activity_class),
              derived);
#endif
        }
        const __m256i slot = _mm256_and_si256(state[c], slot_mask);
        const __m256i entry = gather32<4>(slot_tables, _mm256_add_epi32(model, slot));
        const __m256i symbol = _mm256_and_si256(entry, symbol_mask);
        __m256i next =
            _mm256_add_epi32(_mm256_mullo_epi32(_mm256_srli_epi32(entry, kFreqShift),
                                                _mm256_srli_epi32(state[c], kScaleBits)),
                             _mm256_and_si256(_mm256_srli_epi32(entry, kBiasShift), slot_mask));
#ifdef TESSERA_LANES_AVX512
        // The reading lanes as a mask, and each one's word by an expand of the step's words.
        next = _mm256_mask_blend_epi32(active_lanes, state[c], next);
        const __mmask8 reads = _mm256_mask_cmplt_epu32_mask(active_lanes, next, above16);
        const __m256i words =
            _mm256_cvtepu16_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(words_at[c])));
        next = _mm256_mask_or_epi32(next, reads, _mm256_slli_epi32(next, 16),
                                    _mm256_maskz_expand_epi32(reads, words));
        words_at[c] += 2 * __builtin_popcount(unsigned(reads));
#else
        next = _mm256_blendv_epi8(state[c], next, active);
        const __m256i reads =
            _mm256_and_si256(_mm256_cmpeq_epi32(_mm256_min_epu32(next, low16), next), active);
        // Without a branch on whether any lane reads: which steps read is as good as random, and
        // the mispredicted branch cost more than the load (docs/benchmarks.md, "tenth session").
        // The load stays in the padding, which allows a read at every step (kPadding).
        const int read_mask = _mm256_movemask_ps(_mm256_castsi256_ps(reads));
        const __m256i words =
            _mm256_cvtepu16_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(words_at[c])));
        const __m256i my_words = _mm256_permutevar8x32_epi32(
            words,
            _mm256_load_si256(reinterpret_cast<const __m256i*>(kCompaction.index[read_mask])));
        next =
            _mm256_blendv_epi8(next, _mm256_or_si256(_mm256_slli_epi32(next, 16), my_words), reads);
        words_at[c] += 2 * __builtin_popcount(unsigned(read_mask));
#endif
        state[c] = next;
        symbols[c] = symbol;
      }
      // One test for escapes in any channel (63 is the largest symbol), then each channel's.
      __m256i largest = symbols[0];
      for (uint32_t c = 1; c < kCh; ++c) largest = _mm256_max_epu32(largest, symbols[c]);
      if (_mm256_movemask_ps(_mm256_castsi256_ps(
              _mm256_and_si256(_mm256_cmpeq_epi32(largest, escape), active))) != 0) [[unlikely]]
        for (uint32_t c = 0; c < kCh; ++c) {
          const __m256i escaped = _mm256_and_si256(_mm256_cmpeq_epi32(symbols[c], escape), active);
          const int escape_mask = _mm256_movemask_ps(_mm256_castsi256_ps(escaped));
          if (escape_mask == 0) continue;
          const __m256i bytes = _mm256_cvtepu8_epi32(
              _mm_loadl_epi64(reinterpret_cast<const __m128i*>(escapes_at[c])));
          const __m256i mine = _mm256_permutevar8x32_epi32(
              bytes,
              _mm256_load_si256(reinterpret_cast<const __m256i*>(kCompaction.index[escape_mask])));
          symbols[c] = _mm256_blendv_epi8(symbols[c], mine, escaped);
          // The encoder escapes only what 0..62 cannot say.
          failed =
              _mm256_or_si256(failed, _mm256_and_si256(escaped, _mm256_cmpgt_epi32(escape, mine)));
          escapes_at[c] += __builtin_popcount(unsigned(escape_mask));
        }
      __m256i residual[kCh];
      for (uint32_t c = 0; c < kCh; ++c) {
        // Zigzag back to a signed residual: 0, 1, 2, 3, ... -> 0, -1, 1, -2, ...
        const __m256i code = symbols[c];
        residual[c] = _mm256_xor_si256(_mm256_srli_epi32(code, 1),
                                       _mm256_sub_epi32(zero, _mm256_and_si256(code, one)));
      }
      // The residuals into bytes, and subtract-green undone bytewise: texels are sums modulo 256.
      __m256i coded = zero;
      for (uint32_t c = 0; c < kCh; ++c)
        coded = _mm256_or_si256(
            coded, _mm256_slli_epi32(_mm256_and_si256(residual[c], byte_mask), int(8 * c)));
      if constexpr (kCh >= 3)
        coded = _mm256_add_epi8(coded, _mm256_shuffle_epi8(coded, green_to_red_and_blue));
      __m256i prediction = medians;
      if constexpr (kNearest) prediction = block_parents;
      if constexpr (kCorrected || kLeastSquares) {
        prediction = zero;
        for (uint32_t c = 0; c < kCh; ++c)
          prediction = _mm256_or_si256(prediction, _mm256_slli_epi32(predicted[c], int(8 * c)));
      }
      __m256i values = _mm256_add_epi8(prediction, coded);
      if (derived_mask != 0) {
        // Eq. 3: d = 4 * parent + remainder - a - b - c, the remainder the median expects plus
        // the decoded symbol (predictor 1 expects none).
        const __m256i& parents = block_parents;
        __m256i remainders = zero;
        for (uint32_t c = 0; c < kCh; ++c) {
          const __m256i sum3 = _mm256_add_epi32(
              _mm256_add_epi32(channelOf(left, c), channelOf(up, c)), channelOf(up_left, c));
          const __m256i four_parent = _mm256_slli_epi32(channelOf(parents, c), 2);
          // The guess at d: the median's, or predictor 5's with position 3's weights (the
          // walk's, since a derived lane is never pulled).
          __m256i guess;
          if constexpr (kLeastSquares)
            guess = predicted[c];
          else
            guess = channelOf(medians, c);
          const __m256i expected =
              kNearest ? zero
                       : _mm256_min_epi32(
                             three,
                             _mm256_max_epi32(zero, _mm256_sub_epi32(_mm256_add_epi32(guess, sum3),
                                                                     four_parent)));
          const __m256i remainder_value = _mm256_and_si256(
              _mm256_add_epi32(_mm256_add_epi32(_mm256_sub_epi32(four_parent, sum3), expected),
                               residual[c]),
              byte_mask);
          remainders = _mm256_or_si256(remainders, _mm256_slli_epi32(remainder_value, int(8 * c)));
        }
        values = _mm256_blendv_epi8(values, remainders, derived);
      }
      back3 = back2;
      back2 = back1;
      back1 = values;
      if constexpr (kCorrected)
        for (uint32_t c = 0; c < kCh; ++c) {
          detail3[c] = detail2[c];
          detail2[c] = detail1[c];
          detail1[c] =
              _mm256_sub_epi32(_mm256_slli_epi32(channelOf(values, c), 4), upsampled_value[c]);
          _mm256_storeu_si256(
              reinterpret_cast<__m256i*>(detail_diagonal + c * diagonal_words + size_t(t) * kLanes),
              detail1[c]);
        }
      _mm256_storeu_si256(reinterpret_cast<__m256i*>(diagonal + size_t(t) * kLanes), values);
      // A corrupt stream may run ahead: stop within kCheckSteps of passing its end.
      if (t % kCheckSteps == kCheckSteps - 1 || t + 1 == steps) {
        bool overrun = false;
        for (uint32_t c = 0; c < kCh; ++c)
          overrun |= words_at[c] > s.words_end[c] || escapes_at[c] > s.escapes_end[c];
        if (overrun) return false;
      }
    }
    // The band's texels from its steps into rows: eight at a time (a gather of one row's
    // texels, kLanes words apart, packed to kCh bytes each) while the 32 bytes stored stay in
    // the row, then four bytes a texel (the next texel overwrites what spills into it), then
    // byte by byte.
    for (uint32_t k = 0; k < rows; ++k) {
      uint8_t* row = g.texels + (y0 + k) * stride;
      const uint32_t* from = diagonal + size_t(stepOf(0, k)) * kLanes + k;
      // Octets whose 32 bytes end inside the row: 8 i kCh + 32 <= width kCh.
      const uint32_t octets = width * kCh >= 32 ? (width * kCh - 32) / kCh / 8 + 1 : 0;
      for (uint32_t i = 0; i < octets; ++i) {
        const __m256i texels = _mm256_permutevar8x32_epi32(
            _mm256_shuffle_epi8(gather32<4>(from, octet_at), pack), pack_halves);
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(row), texels);
        row += 8 * kCh;
        from += 8 * kLanes;
      }
      // Texels whose four bytes end inside the row: x * kCh + 4 <= width * kCh.
      const uint32_t whole = width * kCh >= 4 ? (width * kCh - 4) / kCh + 1 : 0;
      for (uint32_t x = 8 * octets; x < whole; ++x) {
        std::memcpy(row, from, 4);
        row += kCh;
        from += kLanes;
      }
      for (uint32_t x = std::max(whole, 8 * octets); x < width; ++x) {
        for (uint32_t c = 0; c < kCh; ++c) row[c] = uint8_t(*from >> (8 * c));
        row += kCh;
        from += kLanes;
      }
    }
  }
  for (uint32_t c = 0; c < kCh; ++c) {
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(s.states[c]), state[c]);
    s.words[c] = words_at[c];
    s.escapes[c] = escapes_at[c];
  }
  return _mm256_testz_si256(failed, failed) != 0;
}

// decodeAvx2 for the tile's channel count.
template <LanePredictor kPredictor>
bool decodeAvx2Channels(uint32_t channels, const Geometry& g, Streams& s, const SlotModels& models,
                        const ParentCopy& parent, uint32_t* diagonal, int32_t* detail_diagonal,
                        const int16_t* shortfall) {
  switch (channels) {
    case 1:
      return decodeAvx2<1, kPredictor, false>(g, s, models, parent, diagonal, detail_diagonal,
                                              shortfall);
    case 2:
      return decodeAvx2<2, kPredictor, false>(g, s, models, parent, diagonal, detail_diagonal,
                                              shortfall);
    case 3:
      if (g.green_led)
        return decodeAvx2<3, kPredictor, true>(g, s, models, parent, diagonal, detail_diagonal,
                                               shortfall);
      return decodeAvx2<3, kPredictor, false>(g, s, models, parent, diagonal, detail_diagonal,
                                              shortfall);
    default:
      if (g.green_led)
        return decodeAvx2<4, kPredictor, true>(g, s, models, parent, diagonal, detail_diagonal,
                                               shortfall);
      return decodeAvx2<4, kPredictor, false>(g, s, models, parent, diagonal, detail_diagonal,
                                              shortfall);
  }
}

}  // namespace

bool decodeSimd(std::span<const uint8_t> section, const Walk& walk, uint32_t channels,
                Predictor predictor, std::span<const rans::Model* const> context_models,
                bool green_led, std::vector<uint8_t>& padded) {
  const bool has_parent = predictor != Predictor::kRoot;
  const bool least_squares = predictor == Predictor::kLeastSquares;
  // Predictor 5 whose weights give predictor 4's estimate none needs nothing of predictor 4's.
  const bool corrected = computesParentCorrectedEstimate(predictor, walk);
  const bool plain = least_squares && !corrected;
  // The decoder's scratch after the streams in `padded`: the parent's copy, predictor 4's
  // block shortfalls in the copy's layout (the copy's texels are read only through its wide
  // rows, so they are not copied), the band's texels by step, from which lane 0 reads
  // the band before's last lane up to stepOf(x + 1, kLanes - 1) for x up to the band's last step,
  // and the copy's wide rows and the band's parent tables (ParentCopy).
  constexpr size_t kAlign = 32;
  auto aligned = [](size_t bytes) { return (bytes + kAlign - 1) / kAlign * kAlign; };
  ParentCopy parent;
  uint32_t parent_rows = 0;
  size_t shortfall_bytes = 0, wide_bytes = 0, band_table_bytes = 0;
  if (has_parent) {
    // The parent texels the blocks read: their own, and for predictors 4 and 5 those beside
    // them.
    auto range = [&](const AxisMap& axis) {
      uint32_t first = axis.parent.front(), last = axis.parent.back();
      if (least_squares || corrected)
        for (const uint32_t neighbour : axis.neighbour) {
          first = std::min(first, neighbour);
          last = std::max(last, neighbour);
        }
      return std::pair{first, last};
    };
    const auto [first_row, last_row] = range(*walk.rows);
    const auto [first_column, last_column] = range(*walk.columns);
    parent.first_row = first_row;
    parent.first_column = first_column;
    parent_rows = last_row - first_row + 1;
    parent.stride = (last_column - first_column + 1) * channels;
    // Predictor 4's shortfalls lie in the copy's layout, and its lookups read four bytes from
    // a shortfall's first.
    if (corrected) shortfall_bytes = aligned(size_t(parent_rows) * parent.stride * 2 + 2);
    parent.wide_stride = bandParentEntries(walk.width) + kLanes - 1;
    wide_bytes = aligned(size_t(parent_rows) * parent.wide_stride * 4);
    band_table_bytes = size_t(bandParentEntries(walk.width)) * kLanes * 4;
  }
  const size_t diagonal_bytes =
      size_t(stepsPerBand(walk.width) + stepOf(1, kLanes - 1)) * kLanes * 4;
  // Predictor 4's departures by step, as the band's texels, per channel.
  const size_t detail_bytes = corrected ? diagonal_bytes * channels : 0;
  Streams streams;
  const size_t scratch_bytes = shortfall_bytes + diagonal_bytes + wide_bytes +
                               band_table_bytes * (least_squares || corrected ? 2 : 1) +
                               detail_bytes;
  if (!parse(section, channels, kAlign + scratch_bytes, padded, streams)) return false;
  Geometry geometry{walk.texels,
                    walk.width,
                    walk.height,
                    channels,
                    has_parent,
                    predictor == Predictor::kParentNearest,
                    corrected,
                    least_squares,
                    walk.parent,
                    walk.columns,
                    walk.rows,
                    context_models.data(),
                    uint32_t(context_models.size() / channels),
                    walk.upsampled,
                    nullptr,
                    walk.ls_weights,
                    {}};
  if (least_squares) sumLeastSquaresWeights(walk.ls_weights, channels, geometry.ls_weight_sums);
  geometry.green_led = green_led;
  SlotModels models;
  slotModels(context_models, models);
  uint8_t* const scratch_end = padded.data() + padded.size();
  uint8_t* scratch = scratch_end - scratch_bytes;
  scratch -= reinterpret_cast<uintptr_t>(scratch) % kAlign;
  int16_t* shortfall = reinterpret_cast<int16_t*>(scratch);
  uint32_t* diagonal = reinterpret_cast<uint32_t*>(scratch + shortfall_bytes);
  auto* detail_diagonal = reinterpret_cast<int32_t*>(scratch + scratch_bytes - detail_bytes);
  if (has_parent) {
    // Word j of a wide row is parent column columns.parent[0] - 8 + j, clamped into the copy's
    // columns: the copy's own from the parent's rows, then its edge texels' copies.
    auto* wide = reinterpret_cast<uint32_t*>(diagonal_bytes + reinterpret_cast<uint8_t*>(diagonal));
    // The copy's first column is at least columns.parent[0] - 1 (a neighbour), word 7 or later.
    const auto inside_from = uint32_t(int64_t(parent.first_column) - walk.columns->parent[0] + 8);
    const uint32_t inside = std::min(parent.stride / channels, parent.wide_stride - inside_from);
    for (uint32_t y = 0; y < parent_rows; ++y) {
      uint32_t* to = wide + size_t(y) * parent.wide_stride;
      widenTexels(walk.parent->row(parent.first_row + y) + size_t(parent.first_column) * channels,
                  channels, inside, to + inside_from);
      std::fill(to, to + inside_from, to[inside_from]);
      std::fill(to + inside_from + inside, to + parent.wide_stride, to[inside_from + inside - 1]);
    }
    parent.wide = wide;
    parent.band_block = wide + wide_bytes / 4;
    if (least_squares || corrected) parent.band_near = parent.band_block + band_table_bytes / 4;
  }
  if (corrected) blockShortfalls(walk, channels, parent, parent_rows, shortfall);
  bool ok = false;
  switch (predictor) {
    case Predictor::kParentNearest:
      ok = decodeAvx2Channels<LanePredictor::kNearest>(channels, geometry, streams, models, parent,
                                                       diagonal, detail_diagonal, shortfall);
      break;
    case Predictor::kParentCorrected:
      ok = decodeAvx2Channels<LanePredictor::kCorrected>(
          channels, geometry, streams, models, parent, diagonal, detail_diagonal, shortfall);
      break;
    case Predictor::kLeastSquares:
      if (plain) {
        ok = decodeAvx2Channels<LanePredictor::kLeastSquaresPlain>(
            channels, geometry, streams, models, parent, diagonal, detail_diagonal, shortfall);
        break;
      }
      ok = decodeAvx2Channels<LanePredictor::kLeastSquares>(
          channels, geometry, streams, models, parent, diagonal, detail_diagonal, shortfall);
      break;
    default:
      ok = decodeAvx2Channels<LanePredictor::kMedian>(channels, geometry, streams, models, parent,
                                                      diagonal, detail_diagonal, shortfall);
  }
  return ok && finished(streams, channels);
}

}  // namespace tessera::detail::ptm::lanes::TESSERA_LANES_ISA
