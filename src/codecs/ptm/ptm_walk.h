#pragma once
// ptm's texel walk (docs/codecs.md, "ptm (6)"), shared by its encoder (codec_ptm.cpp) and its
// decoder (codec_ptm_decode.cpp): Marvie & Bouatouch, "Remote Rendering of Massively Textured
// 3D Scenes Through Progressive Texture Maps", part I. In each 2x2 block three children are
// predicted and their residuals kept, and the fourth follows from the decoded parent and the
// remainder of the integer average (eq. 3). One routine codes and decodes, templated on the
// side that moves the symbols (zstd planes, rANS recorder or reader), so that the two can never
// disagree on a prediction or a context.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <span>
#include <vector>

#include "ptm/ptm_codec.h"
#include "ptm/ptm_least_squares.h"
#include "ptm/ptm_rans.h"

namespace tessera::detail::ptm {

constexpr size_t kHeaderBytes = 2;
constexpr size_t kStreamLengthBytes = 4;

// Where each child texel finds its parent along one axis (ParentTexels explains the offset).
struct AxisMap {
  std::vector<uint32_t> parent;     ///< parent texel index of the block holding this child
  std::vector<uint32_t> neighbour;  ///< the parent texel on this child's side of `parent`
  std::vector<uint8_t> second;      ///< 1 for the second child of its block
  std::vector<uint8_t> full;        ///< 1 when both children of the block lie in the tile
  std::vector<uint8_t> derived;     ///< 1 for the second child of a block wholly in the tile
};

// LOCO-I's median edge detector (Weinberger et al., "The LOCO-I lossless image compression
// algorithm"), written as the median of left, up and left + up - up_left: the same predictor
// without branches. Whether a texel sits on an edge is as hard to guess as the texel, and the
// branches cost the decoder 5-11 % (docs/benchmarks.md, "decoder experiments").
inline int medPredict(int left, int up, int up_left) {
  const int low = std::min(left, up), high = std::max(left, up);
  return std::min(high, std::max(low, left + up - up_left));
}

// Contexts of the rANS coder, per channel: for coded texels, the position in the 2x2 block
// (4) times the activity class (8); then, with a parent, the activity class of remainders.
constexpr uint32_t kActivityClasses = 8;
constexpr uint32_t kCodedContexts = 4 * kActivityClasses;
constexpr uint32_t kParentContexts = kCodedContexts + kActivityClasses;
constexpr uint32_t kRootContexts = kActivityClasses;
// Class boundaries of |left - up_left| + |up - up_left| + |up_right - up| per channel, about
// geometric as LOCO-I's gradient quantiser; set on the codec study's inputs.
constexpr int kActivityBounds[kActivityClasses - 1] = {1, 3, 6, 10, 16, 26, 42};

// Coder 5's activity: half the gradients' plus the errors coded at the left texel (twice) and
// the upper one, in the manner of CALIC's error energy (Wu & Memon, "Context-based, adaptive,
// lossless image coding", d_h + d_v + 2 |e_w|). Where the texture is fine-grained, what the
// predictor just got wrong says more about the next error than the gradients do: 3 % smaller
// on the codec study's photograph, 1 % on the map and the synthetic source. A remainder symbol
// is small by construction (0..3 less the expected one), so it counts twice its magnitude.
// The weights were the best of a small grid on the three inputs (docs/benchmarks.md).
constexpr int kErrorWeightLeft = 2;
constexpr int kErrorWeightUp = 1;
constexpr int kRemainderErrorWeight = 2;

// Coder 6's activity: the parent's gradients at the texel, |P - Ph| + |P - Pv| + |Pd - Ph|
// halved, in place of the decoded neighbours', plus the errors coded at the left texel (three
// times) and the upper one; a coded texel adds how far its prediction lies from its parent
// texel. The parent is whole before the tile is decoded, so it shows where the detail is even
// where the neighbours decoded so far are quiet (the edge of a busy patch), and a prediction
// that disagrees with the parent's mean is likely wrong. With the same predictors, pyramids
// were 2.8 % smaller than coder 5's on the codec study's photograph and within 0.4 % on the
// map and the synthetic source; the weights were the best of a small grid on the three inputs
// (docs/benchmarks.md).
constexpr int kParentErrorWeightLeft = 3;
constexpr int kParentErrorWeightUp = 1;

inline uint32_t activityClass(int activity, uint32_t channels) {
  uint32_t q = 0;
  for (int bound : kActivityBounds) q += activity >= bound * int(channels);
  return q;
}
template <uint32_t kChannels>
inline uint32_t activityClass(int activity) {
  return activityClass(activity, kChannels);
}

// A texel's causal neighbours as offsets from it in a tile of `width` texels of `channels`
// bytes, with LOCO-I's substitutes: on the first row all four are the left texel (none at texel
// (0, 0), which no rule reads), on the first column left, up and up-left are the texel above,
// and on the last column up-right is up.
struct NeighbourOffsets {
  ptrdiff_t left, up, up_left, up_right;
};
inline NeighbourOffsets neighbourOffsets(uint32_t x, uint32_t y, uint32_t width,
                                         uint32_t channels) {
  const ptrdiff_t c1 = ptrdiff_t(channels), s = ptrdiff_t(width) * c1;
  if (y == 0) return {-c1, -c1, -c1, -c1};
  const ptrdiff_t up_right = x + 1 < width ? -s + c1 : -s;
  if (x == 0) return {-s, -s, -s, up_right};
  return {-c1, -s, -s - c1, up_right};
}

// Eq. 3's block sum in sixteenths of a level, 16 (4P + 1.5): a floor-average parent sits 0.375
// below its block's mean.
inline int blockSum16(int parent) {
  return 64 * parent + 24;
}

// Predictor 4's prediction from its estimate in sixteenths.
inline int parentCorrectedPrediction(int estimate) {
  return std::clamp((estimate + 8) >> 4, 0, 255);
}

// Predictor 4's estimate of a coded texel in sixteenths of a level (docs/codecs.md, "ptm (6)"),
// before rounding: the upsampled parent `u[0]` plus the median of the neighbours' departures
// from theirs (`d` the departure plane at the texel, `n` the neighbours' offsets; none at the
// origin), pulled towards eq. 3's block sum when the texel's block lies wholly in the tile
// (`full`; `position` 0-2, `t` the texel, whose block's earlier texels are decoded). `channels`
// and `stride` step to the next texel and row in all three planes.
inline int parentCorrectedEstimate(const int16_t* u, const int16_t* d, const uint8_t* t,
                                   const NeighbourOffsets& n, bool origin, bool full,
                                   uint32_t position, int parent, uint32_t channels,
                                   size_t stride) {
  int estimate = *u;
  // The neighbours' departure from the upsampled parent carries the detail the parent lost.
  if (!origin) estimate += medPredict(d[n.left], d[n.up], d[n.up_left]);
  if (!full) return estimate;
  // Eq. 3 fixes the block's sum; what the texels still to come would need, by the same
  // estimate, pulls this one. Weights 1/2, 1/4, 1/2 of the shortfall per texel still unknown:
  // measured on the codec study's inputs.
  const int sum16 = blockSum16(parent);
  const int detail = estimate - *u;
  const ptrdiff_t cx = ptrdiff_t(channels), sy = ptrdiff_t(stride);
  if (position == 0) {
    const int block = u[0] + u[cx] + u[sy] + u[sy + cx] + 4 * detail;
    return estimate + ((sum16 - block) >> 3);
  }
  if (position == 1) {
    const int block = u[0] + u[sy - cx] + u[sy] + 3 * detail;
    return estimate + (sum16 - 16 * t[-cx] - block) / 12;
  }
  const int block = u[0] + u[cx] + 2 * detail;
  return estimate + ((sum16 - 16 * (t[-sy] + t[-sy + cx]) - block) >> 2);
}

// The zstd coder's side of the texel walk: symbols go to (or come from) one plane per channel.
template <bool kEncode>
struct PlaneCoder {
  static constexpr bool kContexts = false;
  static constexpr bool kChained = false;
  static constexpr bool kErrorActivity = false;
  static constexpr bool kParentActivity = false;
  uint8_t* residuals[4];   ///< per channel: symbols of the coded texels, raster order
  uint8_t* remainders[4];  ///< per channel: eq. 3's remainder symbol of each derived texel
  void residual(uint32_t channel, uint32_t /*context*/, uint8_t& symbol) {
    if constexpr (kEncode)
      *residuals[channel]++ = symbol;
    else
      symbol = *residuals[channel]++;
  }
  void remainder(uint32_t channel, uint32_t /*context*/, uint8_t& symbol) {
    if constexpr (kEncode)
      *remainders[channel]++ = symbol;
    else
      symbol = *remainders[channel]++;
  }
};

// The rANS encoder's side: symbols and their contexts in decoding order, coded afterwards
// (rANS codes backwards). `kChainedContexts`: coders 2, 4, 5 and 6 (codeResiduals);
// `kErrors`: coders 5 and 6 (kErrorWeightLeft); `kParent`: coder 6 (kParentErrorWeightLeft).
template <bool kChainedContexts, bool kErrors, bool kParent = false>
struct RansRecorder {
  static constexpr bool kContexts = true;
  static constexpr bool kChained = kChainedContexts;
  static constexpr bool kErrorActivity = kErrors;
  static constexpr bool kParentActivity = kParent;
  uint8_t* symbols;
  uint8_t* contexts;
  void residual(uint32_t /*channel*/, uint32_t context, uint8_t& symbol) {
    *symbols++ = symbol;
    *contexts++ = uint8_t(context);
  }
  void remainder(uint32_t /*channel*/, uint32_t context, uint8_t& symbol) {
    *symbols++ = symbol;
    *contexts++ = uint8_t(kCodedContexts + context);
  }
};

template <bool kChainedContexts, rans::FamilyId kFamily, bool kErrors, bool kParent>
struct RansReader {
  static constexpr bool kContexts = true;
  static constexpr bool kChained = kChainedContexts;
  static constexpr bool kErrorActivity = kErrors;
  static constexpr bool kParentActivity = kParent;
  rans::Decoder<rans::scaleBits(kFamily)> decoder;
  const rans::Model* models[4][kParentContexts];
  void residual(uint32_t channel, uint32_t context, uint8_t& symbol) {
    symbol = decoder.decode(channel, *models[channel][context]);
  }
  void remainder(uint32_t channel, uint32_t context, uint8_t& symbol) {
    symbol = decoder.decode(channel, *models[channel][kCodedContexts + context]);
  }
  bool failed() const { return decoder.failed(); }
};

// The coder of predictor 5's fitting walk: the walk only gathers the normal equations.
struct DiscardingCoder {
  static constexpr bool kContexts = false;
  static constexpr bool kChained = false;
  static constexpr bool kErrorActivity = false;
  static constexpr bool kParentActivity = false;
  void residual(uint32_t /*channel*/, uint32_t /*context*/, uint8_t& /*symbol*/) {}
  void remainder(uint32_t /*channel*/, uint32_t /*context*/, uint8_t& /*symbol*/) {}
};

// Coders 1 and 2 take their models from family 1, coders 3 to 6 from family 2.
rans::FamilyId familyOf(PtmCoder coder);

// The magnitude of a residual or remainder symbol read as signed (0..128).
inline uint32_t symbolMagnitude(uint8_t symbol) {
  const int value = int8_t(symbol);
  return uint32_t(value < 0 ? -value : value);
}

// Size class of a residual symbol read as signed: 0, 1, 2-3, 4 and more.
inline uint32_t residualSizeClass(uint8_t symbol) {
  const uint32_t size = symbolMagnitude(symbol);
  return size == 0 ? 0 : size == 1 ? 1 : size <= 3 ? 2 : 3;
}

// One texel's residual symbols, handed to `coder` in its channel order. Coders 0 and 1 take
// channels in order, each in its activity class. Coder 2 takes green first (the channel that
// subtract-green leaves whole; with 1 or 2 channels, channel order), and each later channel's
// class follows the size of the residual coded just before it in the same texel: halved after
// a zero, raised by its size class otherwise. Colour channels err together, so that size says
// more than the neighbourhood's activity (9 % smaller on the codec study's photograph).
// Symbols, models and states are per slot, the position in that order.
template <uint32_t kChannels, class Coder>
inline void codeResiduals(Coder& coder, uint32_t position, uint32_t activity_class,
                          uint8_t* symbols) {
  if constexpr (!Coder::kChained) {
    const uint32_t context = position * kActivityClasses + activity_class;
    for (uint32_t c = 0; c < kChannels; ++c) coder.residual(c, context, symbols[c]);
  } else {
    constexpr bool kGreenFirst = kChannels >= 3;
    constexpr uint32_t kOrder[4] = {kGreenFirst ? 1u : 0u, kGreenFirst ? 0u : 1u, 2, 3};
    uint32_t q = activity_class;
    for (uint32_t slot = 0; slot < kChannels; ++slot) {
      uint8_t& symbol = symbols[kOrder[slot]];
      coder.residual(slot, position * kActivityClasses + q, symbol);
      const uint32_t size = residualSizeClass(symbol);
      q = size == 0 ? activity_class / 2 : std::min(kActivityClasses - 1, activity_class + size);
    }
  }
}

// Everything a texel walk needs besides the coder.
struct Walk {
  uint8_t* texels;
  uint32_t width, height;
  const ImageView* parent;
  const AxisMap* columns;
  const AxisMap* rows;
  /// Predictors 4 and 5: the parent upsampled to every texel (null where predictor 5's
  /// weights give predictor 4's estimate none).
  const int16_t* upsampled;
  /// Predictor 4: each decoded texel's departure from the upsampled parent, 16 t - upsampled,
  /// kept for the texels after it instead of recomputed from both planes.
  int16_t* detail;
  /// Coders 5 and 6: each texel's coded error, one entry per texel (kErrorWeightLeft).
  uint16_t* errors;
  /// Predictor 5: weights [position][channel][term] (kLsTerms).
  const int8_t* ls_weights;
  /// Predictor 5's fitting walk (encoder only): where each coded texel's terms go.
  LsFit* ls_fit;
  /// Whether the walk computes predictor 4's estimate: predictor 4 always, predictor 5 where
  /// its weights give the estimate a weight (usesEstimate). `upsampled` and `detail` are then
  /// there, unless prepareWalk was told that the decoder computes its own (`planes`).
  bool estimates;
};

// Whether the walk computes predictor 4's estimate: predictor 4 always, predictor 5 where its
// weights give the estimate a weight (Walk::estimates). Every decoder decides by this.
inline bool computesParentCorrectedEstimate(Predictor predictor, const Walk& walk) {
  return predictor == Predictor::kParentCorrected ||
         (predictor == Predictor::kLeastSquares && walk.estimates);
}

// One routine codes and decodes, so the two can never disagree on a prediction. Encoding reads
// `texels` and hands symbols to `coder`; decoding takes them from `coder` and writes `texels`.
// Arithmetic is modulo 256: bit-exact for any input, and for a floor-average pyramid every
// remainder is 0..3.
template <bool kEncode, uint32_t kChannels, Predictor kPredictor, class Coder>
void codeTexels(const Walk& walk, Coder& coder) {
  uint8_t* const texels = walk.texels;
  const uint32_t width = walk.width, height = walk.height;
  const ImageView* const parent = walk.parent;
  const AxisMap* const columns = walk.columns;
  const AxisMap* const rows = walk.rows;
  const int16_t* const upsampled = walk.upsampled;
  int16_t* const details = walk.detail;
  uint16_t* const errors = walk.errors;
  const int8_t* const ls_weights = walk.ls_weights;
  LsFit* const ls_fit = walk.ls_fit;
  constexpr bool kErrors = Coder::kErrorActivity;
  // Predictor 5 without the upsampled parent: its weights give predictor 4's estimate none,
  // which then reads 0.
  const bool estimates = computesParentCorrectedEstimate(kPredictor, walk);
  // Predictor 4 reads each texel's detail three times, as the left, up and up-left neighbour.
  auto keepDetail = [&](const uint8_t* texel, size_t index) {
    if constexpr (kPredictor == Predictor::kParentCorrected ||
                  kPredictor == Predictor::kLeastSquares)
      if (estimates)
        for (uint32_t c = 0; c < kChannels; ++c)
          details[index + c] = int16_t(16 * texel[c] - upsampled[index + c]);
  };
  constexpr bool kColourTransform = kChannels >= 3;
  constexpr bool kHasParent = kPredictor != Predictor::kRoot;
  constexpr bool kExpectedRemainder = kPredictor == Predictor::kNeighbourMedian ||
                                      kPredictor == Predictor::kParentCorrected ||
                                      kPredictor == Predictor::kLeastSquares;
  constexpr bool kLeastSquares = kPredictor == Predictor::kLeastSquares;
  // Predictor 5: each position's and channel's weight sum (leastSquaresPredictFactored).
  [[maybe_unused]] int ls_weight_sums[kLsSets][4] = {};
  if constexpr (kLeastSquares)
    for (uint32_t set = 0; set < kLsSets; ++set)
      for (uint32_t c = 0; c < kChannels; ++c)
        for (uint32_t k = 0; k < kLsTerms; ++k)
          ls_weight_sums[set][c] += ls_weights[(set * kChannels + c) * kLsTerms + k];
  // Coder 6 at the coarsest level has no parent and codes as coder 5.
  constexpr bool kParentActivity = Coder::kParentActivity && kHasParent;
  constexpr bool kNeighbours =
      kPredictor == Predictor::kRoot || kExpectedRemainder || Coder::kContexts;
  const size_t stride = size_t(width) * kChannels;
  for (uint32_t y = 0; y < height; ++y) {
    // A reader that has run out of input can only fail: stop at the row, not the tile's end.
    if constexpr (requires { coder.failed(); })
      if (coder.failed()) return;
    uint8_t* row = texels + y * stride;
    const uint8_t* up_row = y > 0 ? row - stride : nullptr;
    const uint8_t* parent_row = nullptr;
    const uint8_t* parent_near = nullptr;
    bool derived_row = false;
    uint32_t row_position = 0;
    bool full_row = false;
    if constexpr (kHasParent) {
      parent_row = parent->row(rows->parent[y]);
      parent_near = parent->row(rows->neighbour[y]);
      derived_row = rows->derived[y] != 0;
      row_position = 2u * rows->second[y];
      full_row = rows->full[y] != 0;
    }
    for (uint32_t x = 0; x < width; ++x) {
      uint8_t* texel = row + size_t(x) * kChannels;
      const size_t index = size_t(y) * stride + size_t(x) * kChannels;
      [[maybe_unused]] const size_t texel_index = size_t(y) * width + x;  // for kErrors
      // The offset of the block's parent texel P in parent_row (and of the texel beside it in
      // parent_near).
      [[maybe_unused]] const size_t parent_at =
          kHasParent ? size_t(columns->parent[x]) * kChannels : 0;
      [[maybe_unused]] const size_t parent_side_at =
          kLeastSquares ? size_t(columns->neighbour[x]) * kChannels : 0;
      // Causal neighbours, with LOCO-I's substitutes on the first row and column; offsets from
      // `index` so that the detail plane of predictor 4 can use the same ones.
      ptrdiff_t left = 0, up = 0, up_left = 0, up_right = 0;
      const bool origin = x == 0 && y == 0;
      if constexpr (kNeighbours) {
        const NeighbourOffsets n = neighbourOffsets(x, y, width, kChannels);
        left = n.left;
        up = n.up;
        up_left = n.up_left;
        up_right = n.up_right;
      }
      // Coders 5 and 6: the left and upper texels' coded errors, weighted, with the same
      // substitutes as the texels' (in texel units); none at texel (0, 0).
      [[maybe_unused]] auto neighbourErrors = [&](int weight_left, int weight_up) {
        if (origin) return 0;
        const size_t left_error = y == 0 || x > 0 ? texel_index - 1 : texel_index - width;
        const size_t up_error = y == 0 ? texel_index - 1 : texel_index - width;
        return weight_left * errors[left_error] + weight_up * errors[up_error];
      };
      uint32_t context = 0;
      [[maybe_unused]] int activity = 0;  // coder 6 adds to it per coded texel
      if constexpr (kParentActivity) {
        const size_t jn = size_t(columns->neighbour[x]) * kChannels;
        for (uint32_t c = 0; c < kChannels; ++c) {
          const int p = parent_row[parent_at + c], horizontal = parent_row[jn + c];
          activity += std::abs(p - horizontal) + std::abs(p - parent_near[parent_at + c]) +
                      std::abs(parent_near[jn + c] - horizontal);
        }
        activity = activity / 2 + neighbourErrors(kParentErrorWeightLeft, kParentErrorWeightUp);
        context = activityClass<kChannels>(activity);
      } else if constexpr (Coder::kContexts) {
        if (!origin)
          for (uint32_t c = 0; c < kChannels; ++c) {
            const int n = texel[up + c], nw = texel[up_left + c];
            activity += std::abs(texel[left + c] - nw) + std::abs(n - nw) +
                        std::abs(texel[up_right + c] - n);
          }
        if constexpr (kErrors)
          activity = activity / 2 + neighbourErrors(kErrorWeightLeft, kErrorWeightUp);
        context = activityClass<kChannels>(activity);
      }
      // The errors of the texel, for kErrors.
      [[maybe_unused]] uint32_t error_sum = 0;
      uint32_t position = 0;
      if constexpr (kHasParent) {
        const uint8_t* p = parent_row + parent_at;
        if (derived_row && columns->derived[x]) {
          // Marvie & Bouatouch eq. 3: d = 4 * parent + e - a - b - c.
          const uint8_t* b = up_row + size_t(x) * kChannels;
          const uint8_t* a = b - kChannels;
          const uint8_t* c3 = texel - kChannels;
          for (uint32_t c = 0; c < kChannels; ++c) {
            const uint32_t known = 4u * p[c] - a[c] - b[c] - c3[c];
            // The remainder the neighbours expect: the median's guess at d, through eq. 3.
            uint32_t expected = 0;
            if constexpr (kExpectedRemainder) {
              int guess = medPredict(c3[c], b[c], a[c]);
              if constexpr (kLeastSquares) {
                // Predictor 4's estimate without the block's pull, which fixes no derived texel.
                // (No pointer into the planes where there are none: an offset from null is
                // undefined.)
                int estimate16 = 0;
                if (estimates) {
                  const int16_t* d = details + index + c;
                  estimate16 = upsampled[index + c] + medPredict(d[left], d[up], d[up_left]);
                }
                const int8_t* weights = ls_weights + (3 * kChannels + c) * kLsTerms;
                if (kEncode && ls_fit != nullptr) {
                  int terms[kLsTerms];
                  leastSquaresTerms(texel + c, left, up, up_left, up_right, false, p + c,
                                    parent_row + parent_side_at + c, parent_near + parent_at + c,
                                    parent_near + parent_side_at + c, estimate16, guess, terms);
                  ls_fit->add(3, c, terms, 16 * (texel[c] - guess));
                  guess = leastSquaresPredict(weights, guess, terms);
                } else {
                  guess = leastSquaresPredictFactored(
                      weights, ls_weight_sums[3][c], texel + c, left, up, up_left, up_right, false,
                      p + c, parent_row + parent_side_at + c, parent_near + parent_at + c,
                      parent_near + parent_side_at + c, estimate16, guess);
                }
              }
              guess += a[c] + b[c] + c3[c] - 4 * p[c];
              expected = uint32_t(std::clamp(guess, 0, 3));
            }
            uint8_t symbol;
            if constexpr (kEncode) {
              symbol = uint8_t(texel[c] - known - expected);
              coder.remainder(c, context, symbol);
            } else {
              coder.remainder(c, context, symbol);
              texel[c] = uint8_t(known + expected + symbol);
            }
            if constexpr (kErrors) error_sum += kRemainderErrorWeight * symbolMagnitude(symbol);
          }
          keepDetail(texel, index);
          if constexpr (kErrors) errors[texel_index] = uint16_t(error_sum);
          continue;
        }
        position = row_position + columns->second[x];
      }
      int predicted[4];
      for (uint32_t c = 0; c < kChannels; ++c) {
        if constexpr (kPredictor == Predictor::kRoot || kPredictor == Predictor::kNeighbourMedian) {
          predicted[c] =
              origin ? 0 : medPredict(texel[left + c], texel[up + c], texel[up_left + c]);
        } else if constexpr (kPredictor == Predictor::kParentNearest) {
          predicted[c] = parent_row[parent_at + c];
        } else if constexpr (kPredictor == Predictor::kParentBilinear) {
          const size_t j = parent_at + c;
          const size_t jn = size_t(columns->neighbour[x]) * kChannels + c;
          predicted[c] =
              (9 * parent_row[j] + 3 * parent_row[jn] + 3 * parent_near[j] + parent_near[jn] + 8) >>
              4;
        } else {
          const int estimate =
              estimates ? parentCorrectedEstimate(upsampled + index + c, details + index + c,
                                                  texel + c, {left, up, up_left, up_right}, origin,
                                                  full_row && columns->full[x], position,
                                                  parent_row[parent_at + c], kChannels, stride)
                        : 0;
          if constexpr (kLeastSquares) {
            const int median =
                origin ? 0 : medPredict(texel[left + c], texel[up + c], texel[up_left + c]);
            const int8_t* weights = ls_weights + (position * kChannels + c) * kLsTerms;
            if (kEncode && ls_fit != nullptr) {
              int terms[kLsTerms];
              leastSquaresTerms(texel + c, left, up, up_left, up_right, origin,
                                parent_row + parent_at + c, parent_row + parent_side_at + c,
                                parent_near + parent_at + c, parent_near + parent_side_at + c,
                                estimate, median, terms);
              ls_fit->add(position, c, terms, 16 * (texel[c] - median));
              predicted[c] = leastSquaresPredict(weights, median, terms);
            } else {
              predicted[c] = leastSquaresPredictFactored(
                  weights, ls_weight_sums[position][c], texel + c, left, up, up_left, up_right,
                  origin, parent_row + parent_at + c, parent_row + parent_side_at + c,
                  parent_near + parent_at + c, parent_near + parent_side_at + c, estimate, median);
            }
          } else {
            predicted[c] = parentCorrectedPrediction(estimate);
          }
        }
      }
      if constexpr (kParentActivity) {
        int departure = 0;
        for (uint32_t c = 0; c < kChannels; ++c)
          departure += std::abs(predicted[c] - parent_row[parent_at + c]);
        context = activityClass<kChannels>(activity + departure);
      }
      // Subtract-green on residuals: colour channels share most of their error.
      uint8_t symbols[4];
      if constexpr (kEncode) {
        for (uint32_t c = 0; c < kChannels; ++c) symbols[c] = uint8_t(texel[c] - predicted[c]);
        if constexpr (kColourTransform) {
          symbols[0] = uint8_t(symbols[0] - symbols[1]);
          symbols[2] = uint8_t(symbols[2] - symbols[1]);
        }
      }
      codeResiduals<kChannels>(coder, position, context, symbols);
      if constexpr (kErrors) {
        for (uint32_t c = 0; c < kChannels; ++c) error_sum += symbolMagnitude(symbols[c]);
        errors[texel_index] = uint16_t(error_sum);
      }
      if constexpr (!kEncode) {
        if constexpr (kColourTransform) {
          symbols[0] = uint8_t(symbols[0] + symbols[1]);
          symbols[2] = uint8_t(symbols[2] + symbols[1]);
        }
        for (uint32_t c = 0; c < kChannels; ++c) texel[c] = uint8_t(predicted[c] + symbols[c]);
      }
      keepDetail(texel, index);
    }
  }
}

template <bool kEncode, uint32_t kChannels, class Coder>
void codeWith(Predictor predictor, const Walk& w, Coder& coder) {
  switch (predictor) {
    case Predictor::kRoot: return codeTexels<kEncode, kChannels, Predictor::kRoot>(w, coder);
    case Predictor::kParentNearest:
      return codeTexels<kEncode, kChannels, Predictor::kParentNearest>(w, coder);
    case Predictor::kParentBilinear:
      return codeTexels<kEncode, kChannels, Predictor::kParentBilinear>(w, coder);
    case Predictor::kNeighbourMedian:
      return codeTexels<kEncode, kChannels, Predictor::kNeighbourMedian>(w, coder);
    case Predictor::kParentCorrected:
      return codeTexels<kEncode, kChannels, Predictor::kParentCorrected>(w, coder);
    case Predictor::kLeastSquares:
      return codeTexels<kEncode, kChannels, Predictor::kLeastSquares>(w, coder);
  }
}

template <bool kEncode, class Coder>
void code(Predictor predictor, uint32_t channels, const Walk& walk, Coder& coder) {
  switch (channels) {
    case 1: return codeWith<kEncode, 1>(predictor, walk, coder);
    case 2: return codeWith<kEncode, 2>(predictor, walk, coder);
    case 3: return codeWith<kEncode, 3>(predictor, walk, coder);
    default: return codeWith<kEncode, 4>(predictor, walk, coder);
  }
}

// The walk of `texels` (width x height x channels) with `predictor` and `coder`: the
// parent's axes mapped into `columns` and `rows` (none for predictor 0, whose `parent` may be
// null), the parent upsampled for predictor 4 and for predictor 5 where its weights use
// predictor 4's estimate (usesEstimate), and coders 5 and 6's error plane, all in `state`; or
// why the parent does not fit. `ls_weights` is predictor 5's weights, or null while they are
// still to be fitted: the fit needs every term, and the caller sets Walk::ls_weights after.
// Without the upsampled parent, Walk::upsampled and Walk::detail are null: where the estimate
// is not computed, or where `planes` is false (the SIMD lane decoder, which computes the
// upsampled parent and the departures it needs itself).
Result<Walk> prepareWalk(uint8_t* texels, uint32_t width, uint32_t height, uint32_t channels,
                         const ParentTexels* parent, Predictor predictor, PtmCoder coder,
                         const int8_t* ls_weights, PtmState& state, AxisMap& columns, AxisMap& rows,
                         bool planes = true);

// Symbol counts of one tile: `coded` residuals and `derived` remainders per channel.
struct SymbolCounts {
  size_t coded = 0;
  size_t derived = 0;
};

// Counts a tile's symbols; `columns` and `rows` are null for a tile without a parent.
SymbolCounts countSymbols(uint32_t width, uint32_t height, const AxisMap* columns,
                          const AxisMap* rows);

// The symbol planes of the zstd coder, laid out in `plane`: residuals of each channel, then
// remainders of each channel.
template <bool kEncode>
PlaneCoder<kEncode> planesIn(std::vector<uint8_t>& plane, uint32_t channels,
                             const SymbolCounts& counts) {
  plane.resize((counts.coded + counts.derived) * channels);
  PlaneCoder<kEncode> planes{};
  for (uint32_t c = 0; c < channels; ++c) {
    planes.residuals[c] = plane.data() + c * counts.coded;
    planes.remainders[c] = plane.data() + channels * counts.coded + c * counts.derived;
  }
  return planes;
}

}  // namespace tessera::detail::ptm
