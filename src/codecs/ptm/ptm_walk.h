#pragma once
// ptm's texel walk (docs/codecs.md, "ptm (6)"): Marvie & Bouatouch, "Remote Rendering of
// Massively Textured 3D Scenes Through Progressive Texture Maps", part I. In each 2x2 block
// three children are predicted and their residuals kept, and the fourth follows from the
// decoded parent and the remainder of the integer average (eq. 3). One routine codes and
// decodes, templated on the side that moves the symbols (zstd planes, the rANS recorder or
// reader, the lanes' scalar reader, the encoder's least-squares fitter), so that encoder and
// decoders never disagree on a prediction or a context. Arithmetic is modulo 256: lossless for
// any input, and for a floor-average pyramid every remainder is 0..3.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <vector>

#include "ptm/ptm_codec.h"
#include "ptm/ptm_least_squares.h"

namespace tessera::detail::ptm {

inline constexpr size_t kHeaderBytes = 2;

/// Where each child texel finds its parent along one axis (ParentTexels explains the offset).
struct AxisMap {
  std::vector<uint32_t> parent;     ///< parent texel of the block holding this child
  std::vector<uint32_t> neighbour;  ///< the parent texel on this child's side of `parent`
  std::vector<uint8_t> second;      ///< 1 for the second child of its block
  std::vector<uint8_t> full;        ///< 1 when both children of the block lie in the tile
  std::vector<uint8_t> derived;     ///< 1 for the second child of a block wholly in the tile
};

/// LOCO-I's median edge detector (Weinberger et al.) as the median of left, up and
/// left + up - up_left: the same predictor without branches, which mispredict on texture.
inline int medPredict(int left, int up, int up_left) {
  const int low = std::min(left, up), high = std::max(left, up);
  return std::min(high, std::max(low, left + up - up_left));
}

/// Contexts per channel: a coded texel's block position (4) times its activity class (8), then
/// with a parent the remainders' activity classes.
inline constexpr uint32_t kActivityClasses = 8;
inline constexpr uint32_t kCodedContexts = 4 * kActivityClasses;
inline constexpr uint32_t kParentContexts = kCodedContexts + kActivityClasses;
inline constexpr uint32_t kRootContexts = kActivityClasses;
/// Class bounds of the activity per channel, about geometric as LOCO-I's gradient quantiser.
inline constexpr int kActivityBounds[kActivityClasses - 1] = {1, 3, 6, 10, 16, 26, 42};
inline uint32_t activityClass(int activity, uint32_t channels) {
  uint32_t q = 0;
  for (int bound : kActivityBounds) q += activity >= bound * int(channels);
  return q;
}

/// Coder 6's activity (docs/codecs.md): the errors coded at the left and upper texels, in the
/// manner of CALIC's error energy (Wu & Memon), weighted 3 and 1 beside the parent's gradients,
/// 2 and 1 beside the neighbours' (without a parent); a remainder counts twice its magnitude.
inline constexpr int kParentErrorWeightLeft = 3, kParentErrorWeightUp = 1;
inline constexpr int kErrorWeightLeft = 2, kErrorWeightUp = 1, kRemainderErrorWeight = 2;

/// Coder 7's green-led contexts: red's and blue's class in a coded texel is halved where green's
/// residual is zero and raised by two elsewhere (colour channels err together).
inline constexpr uint32_t kGreenChannel = 1;
constexpr bool followsGreen(uint32_t channel) {
  return channel == 0 || channel == 2;
}
constexpr uint32_t greenLedClass(uint32_t activity_class, bool green_zero) {
  return green_zero ? activity_class / 2 : std::min(activity_class + 2, kActivityClasses - 1);
}

/// A texel's causal neighbours as offsets from it, with LOCO-I's substitutes: on the first row
/// all four are the left texel (none at the origin, which no rule reads), on the first column
/// left, up and up-left are the texel above, and on the last column up-right is up.
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

/// Predictor 4's prediction from its estimate in sixteenths of a level.
inline int parentCorrectedPrediction(int estimate) {
  return std::clamp((estimate + 8) >> 4, 0, 255);
}

/// Predictor 4's estimate of a coded texel in sixteenths (docs/codecs.md): the upsampled parent
/// `u[0]` plus the median of the neighbours' departures `d` from theirs (none at the origin),
/// pulled towards eq. 3's block sum 16 (4P + 1.5) where the block lies wholly in the tile
/// (`full`), by 1/2, 1/4 and 1/2 of the shortfall the texels still to come leave at positions
/// 0, 1 and 2. `t` is the texel, `n` its neighbours; `channels` and `stride` step all planes.
inline int parentCorrectedEstimate(const int16_t* u, const int16_t* d, const uint8_t* t,
                                   const NeighbourOffsets& n, bool origin, bool full,
                                   uint32_t position, int parent, uint32_t channels,
                                   size_t stride) {
  int estimate = *u;
  if (!origin) estimate += medPredict(d[n.left], d[n.up], d[n.up_left]);
  if (!full) return estimate;
  const int sum16 = 64 * parent + 24;
  const int detail = estimate - *u;
  const ptrdiff_t cx = ptrdiff_t(channels), sy = ptrdiff_t(stride);
  if (position == 0)
    return estimate + ((sum16 - (u[0] + u[cx] + u[sy] + u[sy + cx] + 4 * detail)) >> 3);
  if (position == 1)
    return estimate + (sum16 - 16 * t[-cx] - (u[0] + u[sy - cx] + u[sy] + 3 * detail)) / 12;
  return estimate + ((sum16 - 16 * (t[-sy] + t[-sy + cx]) - (u[0] + u[cx] + 2 * detail)) >> 2);
}

/// What a side of the walk does besides moving symbols. kContexts: it needs each symbol's
/// context; kChained: coders 2, 4 and 6 (codeResiduals); kErrors: coder 6's activity;
/// kGreenLed: coder 7's green-led contexts; kFits: it takes predictor 5's terms (fit()).
struct WalkSide {
  static constexpr bool kContexts = false, kChained = false, kErrors = false;
  static constexpr bool kGreenLed = false, kFits = false;
};

/// Coder 0's side: symbols go to (or come from) one plane per channel of residuals and one of
/// remainders.
template <bool kEncode>
struct PlaneCoder : WalkSide {
  uint8_t* residuals[4];
  uint8_t* remainders[4];
  void residual(uint32_t c, uint32_t /*context*/, uint8_t& symbol) { move(residuals[c], symbol); }
  void remainder(uint32_t c, uint32_t /*context*/, uint8_t& symbol) { move(remainders[c], symbol); }
  static void move(uint8_t*& at, uint8_t& symbol) {
    if constexpr (kEncode)
      *at++ = symbol;
    else
      symbol = *at++;
  }
};

/// The rANS encoder's side: symbols and their contexts in decoding order, coded afterwards.
template <bool kChainedContexts, bool kErrorActivity>
struct RansRecorder : WalkSide {
  static constexpr bool kContexts = true, kChained = kChainedContexts, kErrors = kErrorActivity;
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

/// A rANS decoder's side: `models[channel][context]`.
template <bool kChainedContexts, uint32_t kScaleBits, bool kErrorActivity>
struct RansReader : WalkSide {
  static constexpr bool kContexts = true, kChained = kChainedContexts, kErrors = kErrorActivity;
  rans::Decoder<kScaleBits> decoder;
  const rans::Model* models[4][kParentContexts];
  [[gnu::always_inline]] void residual(uint32_t c, uint32_t context, uint8_t& symbol) {
    symbol = decoder.decode(c, *models[c][context]);
  }
  [[gnu::always_inline]] void remainder(uint32_t c, uint32_t context, uint8_t& symbol) {
    symbol = decoder.decode(c, *models[c][kCodedContexts + context]);
  }
  bool failed() const { return decoder.failed(); }
};

/// A symbol read as signed: its magnitude, and (a residual's) size class 0, 1, 2-3, 4 and more.
inline uint32_t symbolMagnitude(uint8_t symbol) {
  const int value = int8_t(symbol);
  return uint32_t(value < 0 ? -value : value);
}
inline uint32_t residualSizeClass(uint8_t symbol) {
  const uint32_t size = symbolMagnitude(symbol);
  return size == 0 ? 0 : size == 1 ? 1 : size <= 3 ? 2 : 3;
}

/// One coded texel's residuals, handed to `coder` in its order. Chained coders take green first
/// (with 1 or 2 channels, channel order), each later slot's class halved after a zero residual
/// and raised by the residual's size class otherwise; their symbols, models and states are per
/// slot. Green-led ones take green first and red's and blue's class from it (greenLedClass).
template <uint32_t kChannels, class Coder>
inline void codeResiduals(Coder& coder, uint32_t position, uint32_t q, uint8_t* symbols) {
  const uint32_t context = position * kActivityClasses + q;
  if constexpr (Coder::kChained) {
    constexpr bool kGreenFirst = kChannels >= 3;
    constexpr uint32_t kOrder[4] = {kGreenFirst ? 1u : 0u, kGreenFirst ? 0u : 1u, 2, 3};
    uint32_t slot_q = q;
    for (uint32_t slot = 0; slot < kChannels; ++slot) {
      uint8_t& symbol = symbols[kOrder[slot]];
      coder.residual(slot, position * kActivityClasses + slot_q, symbol);
      const uint32_t size = residualSizeClass(symbol);
      slot_q = size == 0 ? q / 2 : std::min(kActivityClasses - 1, q + size);
    }
  } else if constexpr (Coder::kGreenLed && kChannels >= 3) {
    coder.residual(kGreenChannel, context, symbols[kGreenChannel]);
    const uint32_t led =
        position * kActivityClasses + greenLedClass(q, symbols[kGreenChannel] == 0);
    for (uint32_t c = 0; c < kChannels; ++c)
      if (c != kGreenChannel) coder.residual(c, followsGreen(c) ? led : context, symbols[c]);
  } else {
    for (uint32_t c = 0; c < kChannels; ++c) coder.residual(c, context, symbols[c]);
  }
}

/// Everything a walk needs besides its side.
struct Walk {
  uint8_t* texels;
  uint32_t width, height;
  const ImageView* parent;  ///< null for predictor 0
  const AxisMap* columns;
  const AxisMap* rows;
  /// Predictors 4 and 5: the parent upsampled to every texel, and each decoded texel's
  /// departure from it (16 t - upsampled); null where prepareWalk was told to leave them out.
  const int16_t* upsampled;
  int16_t* detail;
  uint16_t* errors;          ///< coder 6: each texel's coded error
  const int8_t* ls_weights;  ///< predictor 5: [position][channel][term]
  /// Whether the walk computes predictor 4's estimate: predictor 4 always, predictor 5 where its
  /// weights give the estimate a weight (usesEstimate).
  bool estimates;
};

/// Decides, for every decoder alike, whether `predictor` computes predictor 4's estimate.
inline bool computesParentCorrectedEstimate(Predictor predictor, const Walk& walk) {
  return predictor == Predictor::kParentCorrected ||
         (predictor == Predictor::kLeastSquares && walk.estimates);
}

/// One row of the walk.
struct WalkRow {
  uint32_t y;
  uint8_t* texels;
  const uint8_t* parent_row;   ///< the parent row of the row's blocks
  const uint8_t* parent_near;  ///< the parent row beside it (bilinear upsampling's)
  bool derived;                ///< the second row of blocks wholly in the tile
  bool full;                   ///< its blocks lie wholly in the tile
  uint32_t position;           ///< 2 in a block's second row, else 0
};
inline WalkRow walkRow(const Walk& w, uint32_t y, uint32_t channels) {
  WalkRow r{y, w.texels + size_t(y) * w.width * channels, nullptr, nullptr, false, false, 0};
  if (w.parent != nullptr) {
    r.parent_row = w.parent->row(w.rows->parent[y]);
    r.parent_near = w.parent->row(w.rows->neighbour[y]);
    r.derived = w.rows->derived[y] != 0;
    r.full = w.rows->full[y] != 0;
    r.position = 2u * w.rows->second[y];
  }
  return r;
}

/// A walk's compile-time choices: direction, channels, predictor and side.
template <bool kEncoding, uint32_t kChannelCount, Predictor kPredictorValue, class Side>
struct Kind {
  static constexpr bool kEncode = kEncoding;
  static constexpr uint32_t kChannels = kChannelCount;
  static constexpr Predictor kPredictor = kPredictorValue;
  using Coder = Side;
  static constexpr bool kHasParent = kPredictor != Predictor::kRoot;
  static constexpr bool kLeastSquares = kPredictor == Predictor::kLeastSquares;
  static constexpr bool kEstimates = kPredictor == Predictor::kParentCorrected || kLeastSquares;
  static constexpr bool kExpectedRemainder =
      kEstimates || kPredictor == Predictor::kNeighbourMedian;
  static constexpr bool kErrors = Side::kErrors;
  /// Coder 6 without a parent takes the neighbours' gradients instead of the parent's.
  static constexpr bool kParentActivity = kErrors && kHasParent;
  static constexpr bool kNeighbours =
      kPredictor == Predictor::kRoot || kExpectedRemainder || Side::kContexts;
};

/// The per-texel state codeTexel's parts share.
struct TexelAt {
  uint32_t x;
  uint8_t* texel;
  size_t index;                      ///< of the texel's first byte in the tile and in the planes
  size_t texel_index;                ///< of the texel in the error plane
  size_t parent_at, parent_side_at;  ///< P's and Ph's byte offsets in the parent rows
  NeighbourOffsets n;
  bool origin;
};

/// Predictor 5's texels of channel c (LsTexels).
inline LsTexels lsTexels(const WalkRow& r, const TexelAt& at, uint32_t c) {
  return {at.texel + c,
          at.n.left,
          at.n.up,
          at.n.up_left,
          at.n.up_right,
          at.origin,
          r.parent_row + at.parent_at + c,
          r.parent_row + at.parent_side_at + c,
          r.parent_near + at.parent_at + c,
          r.parent_near + at.parent_side_at + c};
}

/// Coder 6's weighted errors of the left and upper texels, with the texels' substitutes.
inline int neighbourErrors(const Walk& w, const WalkRow& r, const TexelAt& at, int weight_left,
                           int weight_up) {
  if (at.origin) return 0;
  const size_t i = at.texel_index;
  const size_t left = r.y == 0 || at.x > 0 ? i - 1 : i - w.width;
  const size_t up = r.y == 0 ? i - 1 : i - w.width;
  return weight_left * w.errors[left] + weight_up * w.errors[up];
}

/// The texel's activity before its prediction is known (the contexts' class follows from it).
template <class K>
[[gnu::always_inline]] inline int texelActivity(const Walk& w, const WalkRow& r,
                                                const TexelAt& at) {
  constexpr uint32_t kChannels = K::kChannels;
  int activity = 0;
  if constexpr (K::kParentActivity) {
    for (uint32_t c = 0; c < kChannels; ++c) {
      const int p = r.parent_row[at.parent_at + c], side = r.parent_row[at.parent_side_at + c];
      activity += std::abs(p - side) + std::abs(p - r.parent_near[at.parent_at + c]) +
                  std::abs(r.parent_near[at.parent_side_at + c] - side);
    }
    return activity / 2 + neighbourErrors(w, r, at, kParentErrorWeightLeft, kParentErrorWeightUp);
  }
  const uint8_t* t = at.texel;
  if (!at.origin)
    for (uint32_t c = 0; c < kChannels; ++c) {
      const int up = t[at.n.up + c], up_left = t[at.n.up_left + c];
      activity += std::abs(t[at.n.left + c] - up_left) + std::abs(up - up_left) +
                  std::abs(t[at.n.up_right + c] - up);
    }
  if constexpr (K::kErrors)
    activity = activity / 2 + neighbourErrors(w, r, at, kErrorWeightLeft, kErrorWeightUp);
  return activity;
}

/// Whether the walk computes predictor 4's estimate (Walk::estimates), known at compile time
/// for every predictor but 5.
template <class K>
[[gnu::always_inline]] inline bool estimates(const Walk& w) {
  return K::kPredictor == Predictor::kParentCorrected || (K::kLeastSquares && w.estimates);
}

/// Keeps a decoded texel's departures from the upsampled parent for the texels after it.
template <class K>
[[gnu::always_inline]] inline void keepDetail(const Walk& w, const TexelAt& at) {
  if constexpr (K::kEstimates)
    if (estimates<K>(w))
      for (uint32_t c = 0; c < K::kChannels; ++c)
        w.detail[at.index + c] = int16_t(16 * at.texel[c] - w.upsampled[at.index + c]);
}

/// A derived texel (Marvie & Bouatouch eq. 3): d = 4 P + e - a - b - c, with the remainder e
/// less the remainder the guess at d expects (the median's, predictor 5's at position 3 with
/// predictor 4's estimate unpulled; none for predictor 1). Returns the texel's coded error.
template <class K>
[[gnu::always_inline]] inline uint32_t codeDerived(const Walk& w, const WalkRow& r,
                                                   const TexelAt& at, uint32_t q,
                                                   const int (&ls_sums)[kLsSets][4],
                                                   typename K::Coder& coder) {
  constexpr uint32_t kChannels = K::kChannels;
  uint8_t* const texel = at.texel;
  // The block's other texels: a derived texel is never on the first row or column.
  const uint8_t* p = r.parent_row + at.parent_at;
  const uint8_t* b = texel - size_t(w.width) * kChannels;
  const uint8_t* a = b - kChannels;
  const uint8_t* c3 = texel - kChannels;
  uint32_t error_sum = 0;
  for (uint32_t c = 0; c < kChannels; ++c) {
    const uint32_t known = 4u * p[c] - a[c] - b[c] - c3[c];
    uint32_t expected = 0;
    if constexpr (K::kExpectedRemainder) {
      int guess = medPredict(c3[c], b[c], a[c]);
      if constexpr (K::kLeastSquares) {
        int estimate16 = 0;
        if (w.estimates) {
          const int16_t* d = w.detail + at.index + c;
          estimate16 =
              w.upsampled[at.index + c] + medPredict(d[at.n.left], d[at.n.up], d[at.n.up_left]);
        }
        const LsTexels ls = lsTexels(r, at, c);
        if constexpr (K::Coder::kFits) coder.fit(3, c, ls, estimate16, guess, texel[c]);
        guess = leastSquaresPredictFactored(w.ls_weights + (3 * kChannels + c) * kLsTerms,
                                            ls_sums[3][c], ls, estimate16, guess);
      }
      expected = uint32_t(std::clamp(guess + a[c] + b[c] + c3[c] - 4 * p[c], 0, 3));
    }
    uint8_t symbol;
    if constexpr (K::kEncode) {
      symbol = uint8_t(texel[c] - known - expected);
      coder.remainder(c, q, symbol);
    } else {
      coder.remainder(c, q, symbol);
      texel[c] = uint8_t(known + expected + symbol);
    }
    if constexpr (K::kErrors) error_sum += kRemainderErrorWeight * symbolMagnitude(symbol);
  }
  return error_sum;
}

/// A coded texel's prediction of channel c at block `position`.
template <class K>
[[gnu::always_inline]] inline int predictTexel(const Walk& w, const WalkRow& r, const TexelAt& at,
                                               uint32_t position, uint32_t c,
                                               const int (&ls_sums)[kLsSets][4],
                                               typename K::Coder& coder) {
  const uint8_t* t = at.texel;
  if constexpr (K::kPredictor == Predictor::kParentNearest) return r.parent_row[at.parent_at + c];
  const int median =
      at.origin ? 0 : medPredict(t[at.n.left + c], t[at.n.up + c], t[at.n.up_left + c]);
  if constexpr (!K::kEstimates) return median;
  const int estimate =
      estimates<K>(w)
          ? parentCorrectedEstimate(w.upsampled + at.index + c, w.detail + at.index + c, t + c,
                                    at.n, at.origin, r.full && w.columns->full[at.x], position,
                                    r.parent_row[at.parent_at + c], K::kChannels,
                                    size_t(w.width) * K::kChannels)
          : 0;
  if constexpr (!K::kLeastSquares) return parentCorrectedPrediction(estimate);
  const LsTexels ls = lsTexels(r, at, c);
  if constexpr (K::Coder::kFits) coder.fit(position, c, ls, estimate, median, t[c]);
  return leastSquaresPredictFactored(w.ls_weights + (position * K::kChannels + c) * kLsTerms,
                                     ls_sums[position][c], ls, estimate, median);
}

/// Texel x of row `r`: its context, then eq. 3 for a derived texel or its prediction and
/// residuals (subtract-green on 3 and 4 channels: colour channels share most of their error).
template <class K>
[[gnu::always_inline]] inline void codeTexel(const Walk& w, const WalkRow& r, uint32_t x,
                                             const int (&ls_sums)[kLsSets][4],
                                             typename K::Coder& coder) {
  constexpr uint32_t kChannels = K::kChannels;
  TexelAt at{x,
             r.texels + size_t(x) * kChannels,
             (size_t(r.y) * w.width + x) * kChannels,
             size_t(r.y) * w.width + x,
             0,
             0,
             {0, 0, 0, 0},
             x == 0 && r.y == 0};
  if constexpr (K::kHasParent) at.parent_at = size_t(w.columns->parent[x]) * kChannels;
  if constexpr (K::kLeastSquares || K::kParentActivity)
    at.parent_side_at = size_t(w.columns->neighbour[x]) * kChannels;
  if constexpr (K::kNeighbours) at.n = neighbourOffsets(x, r.y, w.width, kChannels);
  int activity = 0;
  if constexpr (K::Coder::kContexts) activity = texelActivity<K>(w, r, at);
  uint32_t q = K::Coder::kContexts ? activityClass(activity, kChannels) : 0;
  uint32_t position = 0;
  if constexpr (K::kHasParent) {
    if (r.derived && w.columns->derived[x]) {
      const uint32_t error = codeDerived<K>(w, r, at, q, ls_sums, coder);
      keepDetail<K>(w, at);
      if constexpr (K::kErrors) w.errors[at.texel_index] = uint16_t(error);
      return;
    }
    position = r.position + w.columns->second[x];
  }
  int predicted[4];
  for (uint32_t c = 0; c < kChannels; ++c)
    predicted[c] = predictTexel<K>(w, r, at, position, c, ls_sums, coder);
  if constexpr (K::kParentActivity) {
    int departure = 0;
    for (uint32_t c = 0; c < kChannels; ++c)
      departure += std::abs(predicted[c] - r.parent_row[at.parent_at + c]);
    q = activityClass(activity + departure, kChannels);
  }
  uint8_t* const texel = at.texel;
  uint8_t symbols[4];
  if constexpr (K::kEncode) {
    for (uint32_t c = 0; c < kChannels; ++c) symbols[c] = uint8_t(texel[c] - predicted[c]);
    if constexpr (kChannels >= 3) {
      symbols[0] = uint8_t(symbols[0] - symbols[1]);
      symbols[2] = uint8_t(symbols[2] - symbols[1]);
    }
  }
  codeResiduals<kChannels>(coder, position, q, symbols);
  if constexpr (K::kErrors) {
    uint32_t error = 0;
    for (uint32_t c = 0; c < kChannels; ++c) error += symbolMagnitude(symbols[c]);
    w.errors[at.texel_index] = uint16_t(error);
  }
  if constexpr (!K::kEncode) {
    if constexpr (kChannels >= 3) {
      symbols[0] = uint8_t(symbols[0] + symbols[1]);
      symbols[2] = uint8_t(symbols[2] + symbols[1]);
    }
    for (uint32_t c = 0; c < kChannels; ++c) texel[c] = uint8_t(predicted[c] + symbols[c]);
  }
  keepDetail<K>(w, at);
}

/// Rows decoded side by side in coder 7's order (ptm_lanes.h): in each band of kLaneRows rows,
/// row k codes texel x = t - 2 k at step t, so that every neighbour a texel reads was coded at
/// an earlier step.
inline constexpr uint32_t kLaneRows = 8;
constexpr uint32_t stepsPerBand(uint32_t width) {
  return width + 2 * (kLaneRows - 1);
}

/// The walk of the whole tile: raster order, or for a side with `lane` (coder 7's scalar
/// reader) band by band in coder 7's order, telling the side each texel's row of the band.
template <class K>
void codeTexels(const Walk& walk, typename K::Coder& coder) {
  const Walk w = walk;  // a local copy: stores through the texels cannot alias it
  int ls_sums[kLsSets][4] = {};
  if constexpr (K::kLeastSquares) sumLeastSquaresWeights(w.ls_weights, K::kChannels, ls_sums);
  if constexpr (requires { coder.lane; }) {
    for (uint32_t y0 = 0; y0 < w.height; y0 += kLaneRows) {
      const uint32_t rows = std::min(kLaneRows, w.height - y0);
      WalkRow band[kLaneRows];
      for (uint32_t k = 0; k < rows; ++k) band[k] = walkRow(w, y0 + k, K::kChannels);
      for (uint32_t t = 0; t < stepsPerBand(w.width) && !coder.failed(); ++t)
        for (uint32_t k = 0; k < rows; ++k) {
          if (t < 2 * k || t - 2 * k >= w.width) continue;
          coder.lane = k;
          codeTexel<K>(w, band[k], t - 2 * k, ls_sums, coder);
        }
    }
  } else {
    for (uint32_t y = 0; y < w.height; ++y) {
      // A reader that has run out of input can only fail: stop at the row.
      if constexpr (requires { coder.failed(); })
        if (coder.failed()) return;
      const WalkRow r = walkRow(w, y, K::kChannels);
      for (uint32_t x = 0; x < w.width; ++x) codeTexel<K>(w, r, x, ls_sums, coder);
    }
  }
}

template <bool kEncode, uint32_t kChannels, class Coder>
void codeWith(Predictor predictor, const Walk& w, Coder& coder) {
  switch (predictor) {
    case Predictor::kRoot:
      return codeTexels<Kind<kEncode, kChannels, Predictor::kRoot, Coder>>(w, coder);
    case Predictor::kParentNearest:
      return codeTexels<Kind<kEncode, kChannels, Predictor::kParentNearest, Coder>>(w, coder);
    case Predictor::kNeighbourMedian:
      return codeTexels<Kind<kEncode, kChannels, Predictor::kNeighbourMedian, Coder>>(w, coder);
    case Predictor::kParentCorrected:
      return codeTexels<Kind<kEncode, kChannels, Predictor::kParentCorrected, Coder>>(w, coder);
    case Predictor::kLeastSquares:
      return codeTexels<Kind<kEncode, kChannels, Predictor::kLeastSquares, Coder>>(w, coder);
  }
}

/// Codes (kEncode: reads the texels, hands `coder` the symbols) or decodes (takes the symbols,
/// writes the texels) the walk of `predictor`.
template <bool kEncode, class Coder>
void code(Predictor predictor, uint32_t channels, const Walk& walk, Coder& coder) {
  switch (channels) {
    case 1: return codeWith<kEncode, 1>(predictor, walk, coder);
    case 2: return codeWith<kEncode, 2>(predictor, walk, coder);
    case 3: return codeWith<kEncode, 3>(predictor, walk, coder);
    default: return codeWith<kEncode, 4>(predictor, walk, coder);
  }
}

/// The walk of `texels` (width x height x channels) with `predictor`: the parent's axes mapped
/// into `columns` and `rows`, predictor 4's planes (for predictor 5 where `ls_weights` use its
/// estimate, or are null: still to be fitted) unless `planes` is false, and coder 6's error
/// plane, all in `state`; or kInvalidArgument where the parent does not fit.
Result<Walk> prepareWalk(uint8_t* texels, uint32_t width, uint32_t height, uint32_t channels,
                         const ParentTexels* parent, Predictor predictor, PtmCoder coder,
                         const int8_t* ls_weights, PtmState& state, AxisMap& columns, AxisMap& rows,
                         bool planes = true);

/// Coder 0's symbol counts per channel: `coded` residuals and `derived` remainders.
struct SymbolCounts {
  size_t coded = 0;
  size_t derived = 0;
};
SymbolCounts countSymbols(const Walk& walk);

/// Coder 0's planes in `plane`: the residuals of each channel, then the remainders of each.
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
