// ptm: progressive texture maps (Marvie & Bouatouch, "Remote Rendering of Massively Textured 3D
// Scenes Through Progressive Texture Maps", part I). A tile is coded as what its decoded parent
// does not already say: in each 2x2 block three children are predicted and their residuals
// kept, and the fourth follows from the parent and the remainder of the integer average
// (eq. 3). Byte layout and the measurements behind the choices: docs/codecs.md, "ptm (6)".
#include <algorithm>
#include <cstring>
#include <memory>

#include <fmt/format.h>

#include "codec_internal.h"
#include "ptm_least_squares.h"
#include "ptm_rans.h"

namespace tessera::detail {

namespace {

constexpr size_t kHeaderBytes = 2;
constexpr size_t kStreamLengthBytes = 4;

// Levels 1-9 gave sizes within 1 % of each other on residual planes (Huffman-coded literals
// with few matches), so the cheapest level wins: the builder encodes every tile.
constexpr int kDefaultZstdLevel = 1;

// Where each child texel finds its parent along one axis (ParentTexels explains the offset).
struct AxisMap {
  std::vector<uint32_t> parent;     ///< parent texel index of the block holding this child
  std::vector<uint32_t> neighbour;  ///< the parent texel on this child's side of `parent`
  std::vector<uint8_t> second;      ///< 1 for the second child of its block
  std::vector<uint8_t> full;        ///< 1 when both children of the block lie in the tile
  std::vector<uint8_t> derived;     ///< 1 for the second child of a block wholly in the tile
};

// Returns false when a child texel's block falls outside the parent tile: the caller passed
// geometry that does not come from one image's quadtree.
bool mapAxis(uint32_t child_px, uint32_t parent_px, uint64_t offset, AxisMap& map) {
  map.parent.resize(child_px);
  map.neighbour.resize(child_px);
  map.second.resize(child_px);
  map.full.resize(child_px);
  map.derived.resize(child_px);
  for (uint32_t i = 0; i < child_px; ++i) {
    const uint64_t u = offset + i;
    const uint64_t j = u >> 1;
    if (j >= parent_px) return false;
    const bool second = (u & 1) != 0;
    map.parent[i] = uint32_t(j);
    // Bilinear upsampling weights the parent texel on the child's side of its block.
    map.neighbour[i] =
        second ? uint32_t(std::min<uint64_t>(j + 1, parent_px - 1)) : uint32_t(j == 0 ? 0 : j - 1);
    map.second[i] = second;
    // A block whose first child lies before the tile (odd border) is coded texel by texel.
    map.full[i] = second ? i > 0 : i + 1 < child_px;
    map.derived[i] = second && i > 0;
  }
  return true;
}

// LOCO-I's median edge detector (Weinberger et al., "The LOCO-I lossless image compression
// algorithm").
inline int medPredict(int left, int up, int up_left) {
  const int low = std::min(left, up), high = std::max(left, up);
  if (up_left >= high) return low;
  if (up_left <= low) return high;
  return left + up - up_left;
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

template <uint32_t kChannels>
inline uint32_t activityClass(int activity) {
  uint32_t q = 0;
  for (int bound : kActivityBounds) q += activity >= bound * int(kChannels);
  return q;
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
rans::FamilyId familyOf(PtmCoder coder) {
  return coder == PtmCoder::kRans || coder == PtmCoder::kRansChained ? rans::FamilyId::kGeometric12
                                                                     : rans::FamilyId::kMixture15;
}

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

// The parent bilinearly upsampled to every child texel, times 16, plus 6: a floor-average
// parent sits 0.375 below its block's mean.
template <uint32_t kChannels>
void upsampleParent(const ImageView& parent, const AxisMap& columns, const AxisMap& rows,
                    int16_t* out) {
  const uint32_t width = uint32_t(columns.parent.size()), height = uint32_t(rows.parent.size());
  for (uint32_t y = 0; y < height; ++y) {
    const uint8_t* parent_row = parent.row(rows.parent[y]);
    const uint8_t* parent_near = parent.row(rows.neighbour[y]);
    for (uint32_t x = 0; x < width; ++x) {
      const size_t j = size_t(columns.parent[x]) * kChannels;
      const size_t jn = size_t(columns.neighbour[x]) * kChannels;
      for (uint32_t c = 0; c < kChannels; ++c)
        *out++ = int16_t(9 * parent_row[j + c] + 3 * parent_row[jn + c] + 3 * parent_near[j + c] +
                         parent_near[jn + c] + 6);
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
};

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
  // Predictor 4 reads each texel's detail three times, as the left, up and up-left neighbour.
  auto keepDetail = [&](const uint8_t* texel, size_t index) {
    if constexpr (kPredictor == Predictor::kParentCorrected ||
                  kPredictor == Predictor::kLeastSquares)
      for (uint32_t c = 0; c < kChannels; ++c)
        details[index + c] = int16_t(16 * texel[c] - upsampled[index + c]);
  };
  constexpr bool kColourTransform = kChannels >= 3;
  constexpr bool kHasParent = kPredictor != Predictor::kRoot;
  constexpr bool kExpectedRemainder = kPredictor == Predictor::kNeighbourMedian ||
                                      kPredictor == Predictor::kParentCorrected ||
                                      kPredictor == Predictor::kLeastSquares;
  constexpr bool kLeastSquares = kPredictor == Predictor::kLeastSquares;
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
        const ptrdiff_t c1 = ptrdiff_t(kChannels), s = ptrdiff_t(stride);
        if (y == 0) {
          left = up = up_left = up_right = -c1;
        } else if (x == 0) {
          left = up = up_left = -s;
          up_right = x + 1 < width ? -s + c1 : -s;
        } else {
          left = -c1;
          up = -s;
          up_left = -s - c1;
          up_right = x + 1 < width ? -s + c1 : -s;
        }
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
                const int16_t* d = details + index + c;
                const int estimate16 =
                    upsampled[index + c] + medPredict(d[left], d[up], d[up_left]);
                int terms[kLsTerms];
                leastSquaresTerms(texel + c, left, up, up_left, up_right, false, p + c,
                                  parent_row + parent_side_at + c, parent_near + parent_at + c,
                                  parent_near + parent_side_at + c, estimate16, guess, terms);
                if constexpr (kEncode)
                  if (ls_fit != nullptr) ls_fit->add(3, c, terms, 16 * (texel[c] - guess));
                guess =
                    leastSquaresPredict(ls_weights + (3 * kChannels + c) * kLsTerms, guess, terms);
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
          const int16_t* u = upsampled + index + c;
          const uint8_t* t = texel + c;
          const int16_t* d = details + index + c;
          int estimate = *u;
          if (!origin) {
            // The neighbours' departure from the upsampled parent carries the detail the
            // parent lost.
            estimate += medPredict(d[left], d[up], d[up_left]);
          }
          if (full_row && columns->full[x]) {
            // Eq. 3 fixes the block's sum; what the texels still to come would need, by the
            // same estimate, pulls this one. Weights 1/2, 1/4, 1/2 of the shortfall per texel
            // still unknown: measured on the codec study's inputs.
            const int sum16 = 64 * parent_row[parent_at + c] + 24;
            const int detail = estimate - *u;
            const ptrdiff_t cx = ptrdiff_t(kChannels), sy = ptrdiff_t(stride);
            if (position == 0) {
              const int block = u[0] + u[cx] + u[sy] + u[sy + cx] + 4 * detail;
              estimate += (sum16 - block) >> 3;
            } else if (position == 1) {
              const int block = u[0] + u[sy - cx] + u[sy] + 3 * detail;
              estimate += (sum16 - 16 * t[-cx] - block) / 12;
            } else {
              const int block = u[0] + u[cx] + 2 * detail;
              estimate += (sum16 - 16 * (t[-sy] + t[-sy + cx]) - block) >> 2;
            }
          }
          if constexpr (kLeastSquares) {
            const int median =
                origin ? 0 : medPredict(texel[left + c], texel[up + c], texel[up_left + c]);
            int terms[kLsTerms];
            leastSquaresTerms(texel + c, left, up, up_left, up_right, origin,
                              parent_row + parent_at + c, parent_row + parent_side_at + c,
                              parent_near + parent_at + c, parent_near + parent_side_at + c,
                              estimate, median, terms);
            if constexpr (kEncode)
              if (ls_fit != nullptr) ls_fit->add(position, c, terms, 16 * (texel[c] - median));
            predicted[c] = leastSquaresPredict(ls_weights + (position * kChannels + c) * kLsTerms,
                                               median, terms);
          } else {
            predicted[c] = std::clamp((estimate + 8) >> 4, 0, 255);
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

void upsample(uint32_t channels, const ImageView& parent, const AxisMap& columns,
              const AxisMap& rows, std::vector<int16_t>& out, std::vector<int16_t>& detail) {
  out.resize(columns.parent.size() * rows.parent.size() * channels);
  detail.resize(out.size());
  switch (channels) {
    case 1: return upsampleParent<1>(parent, columns, rows, out.data());
    case 2: return upsampleParent<2>(parent, columns, rows, out.data());
    case 3: return upsampleParent<3>(parent, columns, rows, out.data());
    default: return upsampleParent<4>(parent, columns, rows, out.data());
  }
}

// Fits predictor 5's weights to the tile `walk` covers (its ls_weights, zero, are read but
// do not matter: the fit uses the texels, not the predictions) into `weights`.
void fitLeastSquares(const Walk& walk, uint32_t channels, int8_t* weights) {
  auto fit = std::make_unique<LsFit>();
  Walk fitting = walk;
  fitting.ls_fit = fit.get();
  fitting.errors = nullptr;
  DiscardingCoder discard;
  code<true>(Predictor::kLeastSquares, channels, fitting, discard);
  solveLeastSquares(*fit, channels, weights);
}

// Coders 5 and 6's error plane in `state`, sized to the tile; null for the other coders.
uint16_t* errorPlane(PtmCoder coder, uint32_t width, uint32_t height, CodecScratch::State& state) {
  if (!isErrorActivityCoder(coder)) return nullptr;
  state.errors.resize(size_t(width) * height);
  return state.errors.data();
}

// Symbol counts of one tile: `coded` residuals and `derived` remainders per channel.
struct SymbolCounts {
  size_t coded = 0;
  size_t derived = 0;
};

SymbolCounts countSymbols(uint32_t width, uint32_t height, const AxisMap* columns,
                          const AxisMap* rows) {
  const size_t total = size_t(width) * height;
  if (columns == nullptr) return {total, 0};
  size_t derived_columns = 0, derived_rows = 0;
  for (uint8_t d : columns->derived) derived_columns += d;
  for (uint8_t d : rows->derived) derived_rows += d;
  const size_t derived = derived_columns * derived_rows;
  return {total - derived, derived};
}

// Maps both axes, or explains why the parent does not fit.
Result<void> mapParent(const ImageView& parent_view, const ParentTexels& parent, uint32_t width,
                       uint32_t height, uint32_t channels, AxisMap& columns, AxisMap& rows) {
  if (parent_view.channels != channels)
    return fail(ErrorCode::kInvalidArgument, fmt::format("ptm: parent has {} channels, tile {}",
                                                         parent_view.channels, channels));
  if (parent.quadrant_x > 1 || parent.quadrant_y > 1 ||
      !mapAxis(width, parent_view.width_px,
               uint64_t(parent.quadrant_x) * parent.tile_size_px + parent.border_px, columns) ||
      !mapAxis(height, parent_view.height_px,
               uint64_t(parent.quadrant_y) * parent.tile_size_px + parent.border_px, rows))
    return fail(
        ErrorCode::kInvalidArgument,
        fmt::format("ptm: a {}x{} tile in quadrant ({},{}) at tile size {}, border {} "
                    "does not fit its {}x{} parent",
                    width, height, parent.quadrant_x, parent.quadrant_y, parent.tile_size_px,
                    parent.border_px, parent_view.width_px, parent_view.height_px));
  return {};
}

void appendU32(std::vector<uint8_t>& out, uint32_t value) {
  for (int i = 0; i < 4; ++i) out.push_back(uint8_t(value >> (8 * i)));
}

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

// Decodes a rANS coder's model bytes and stream into walk.texels.
template <bool kChained, rans::FamilyId kFamily, bool kErrors = false, bool kParent = false>
Result<void> decodeRans(std::span<const uint8_t> payload, size_t body_at, Predictor predictor,
                        uint32_t channels, uint32_t contexts, const Walk& walk) {
  const size_t params_bytes = size_t(contexts) * channels;
  if (payload.size() - body_at < params_bytes)
    return fail(ErrorCode::kCorrupt,
                fmt::format("ptm payload: {} bytes, shorter than its {} model parameters",
                            payload.size(), params_bytes));
  RansReader<kChained, kFamily, kErrors, kParent> reader;
  const rans::Model* family = rans::models(kFamily);
  // Every parameter byte names a model, so a corrupt one shows only as a stream that does not
  // finish cleanly (checked below), and then only if its context is used.
  static_assert(rans::kModelCount == 256);
  for (uint32_t c = 0; c < channels; ++c)
    for (uint32_t k = 0; k < contexts; ++k)
      reader.models[c][k] = &family[payload[body_at + c * contexts + k]];
  if (!reader.decoder.start(payload.subspan(body_at + params_bytes), channels))
    return fail(ErrorCode::kCorrupt,
                "ptm payload: rANS stream too short for its initial states, or one is out of "
                "range");
  code<false>(predictor, channels, walk, reader);
  if (!reader.decoder.finishedCleanly(channels))
    return fail(ErrorCode::kCorrupt,
                "ptm payload: rANS stream truncated, corrupt or followed by trailing bytes");
  return {};
}

// encodePtm, or with `estimated_bytes` and a rANS coder only the payload's size to within a
// few bytes: the texel walk and the model choice, without the rANS pass (a quarter of a
// tile's encoding time), for choosing between predictors and coders.
// With `recording` (a rANS coder only), only the walk: its symbols, contexts and header go
// there, for estimateRecordedPtm and encodeRecordedPtm.
Result<std::vector<uint8_t>> encodePtmOrEstimate(const ImageView& tile,
                                                 const EncodeOptions& options,
                                                 const ParentTexels* parent, Predictor predictor,
                                                 PtmCoder coder, CodecScratch* scratch,
                                                 PtmLeastSquaresFit* fit, size_t* estimated_bytes,
                                                 PtmRecording* recording = nullptr) {
  ScratchRef state(scratch);
  const uint32_t width = tile.width_px, height = tile.height_px, channels = tile.channels;
  if (parent == nullptr) predictor = Predictor::kRoot;
  AxisMap columns, rows;
  const bool has_parent = predictor != Predictor::kRoot;
  if (has_parent)
    TESSERA_TRY(mapParent(parent->texels, *parent, width, height, channels, columns, rows));
  if (predictor == Predictor::kParentCorrected || predictor == Predictor::kLeastSquares)
    upsample(channels, parent->texels, columns, rows, state->upsampled, state->detail);
  std::span<const uint8_t> packed = packedTexels(tile, *state);
  int8_t ls_weights[lsWeightBytes(4)] = {};
  // Encoding only reads the texels; the shared routine takes a mutable pointer for decoding.
  const Walk walk{const_cast<uint8_t*>(packed.data()),
                  width,
                  height,
                  has_parent ? &parent->texels : nullptr,
                  &columns,
                  &rows,
                  state->upsampled.data(),
                  state->detail.data(),
                  errorPlane(coder, width, height, *state),
                  ls_weights,
                  nullptr};
  std::vector<uint8_t> payload = {uint8_t(predictor), uint8_t(coder)};
  if (predictor == Predictor::kLeastSquares) {
    static_assert(sizeof fit->weights == sizeof ls_weights);
    if (fit != nullptr && fit->fitted) {
      std::memcpy(ls_weights, fit->weights, sizeof ls_weights);
    } else {
      fitLeastSquares(walk, channels, ls_weights);
      if (fit != nullptr) {
        std::memcpy(fit->weights, ls_weights, sizeof ls_weights);
        fit->fitted = true;
      }
    }
    for (size_t i = 0; i < lsWeightBytes(channels); ++i) payload.push_back(uint8_t(ls_weights[i]));
  }

  if (isRansCoder(coder)) {
    PtmRecording local;
    PtmRecording& out = recording != nullptr ? *recording : local;
    out.coder = coder;
    out.channels = channels;
    out.contexts = has_parent ? kParentContexts : kRootContexts;
    out.header = std::move(payload);
    const size_t symbols = size_t(width) * height * channels;
    out.symbols.resize(symbols);
    out.symbol_contexts.resize(symbols);
    uint8_t* const symbols_at = out.symbols.data();
    uint8_t* const contexts_at = out.symbol_contexts.data();
    if (isParentActivityCoder(coder)) {
      RansRecorder<true, true, true> recorder{symbols_at, contexts_at};
      code<true>(predictor, channels, walk, recorder);
    } else if (isErrorActivityCoder(coder)) {
      RansRecorder<true, true> recorder{symbols_at, contexts_at};
      code<true>(predictor, channels, walk, recorder);
    } else if (isChainedCoder(coder)) {
      RansRecorder<true, false> recorder{symbols_at, contexts_at};
      code<true>(predictor, channels, walk, recorder);
    } else {
      RansRecorder<false, false> recorder{symbols_at, contexts_at};
      code<true>(predictor, channels, walk, recorder);
    }
    if (recording != nullptr) return std::vector<uint8_t>{};
    if (estimated_bytes != nullptr) {
      *estimated_bytes = estimateRecordedPtm(out, coder);
      return std::vector<uint8_t>{};
    }
    return encodeRecordedPtm(out, coder, scratch);
  }

  const SymbolCounts counts =
      countSymbols(width, height, has_parent ? &columns : nullptr, has_parent ? &rows : nullptr);
  PlaneCoder<true> planes = planesIn<true>(state->plane, channels, counts);
  const PlaneCoder<true> starts = planes;
  code<true>(predictor, channels, walk, planes);
  const int level = options.effort != 0 ? options.effort : kDefaultZstdLevel;
  auto addStream = [&](const uint8_t* symbols, size_t count) -> Result<void> {
    if (count == 0) {
      appendU32(payload, 0);
      return {};
    }
    TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> frame,
                             compressZstdFrame({symbols, count}, level, "ptm payload", *state));
    appendU32(payload, uint32_t(frame.size()));
    payload.insert(payload.end(), frame.begin(), frame.end());
    return {};
  };
  // The compressed frames reuse state->compressed, so the planes stay valid throughout.
  for (uint32_t c = 0; c < channels; ++c) TESSERA_TRY(addStream(starts.residuals[c], counts.coded));
  if (has_parent)
    for (uint32_t c = 0; c < channels; ++c)
      TESSERA_TRY(addStream(starts.remainders[c], counts.derived));
  if (estimated_bytes != nullptr) *estimated_bytes = payload.size();
  return payload;
}

}  // namespace

Result<std::vector<uint8_t>> encodePtm(const ImageView& tile, const EncodeOptions& options,
                                       const ParentTexels* parent, Predictor predictor,
                                       PtmCoder coder, CodecScratch* scratch,
                                       PtmLeastSquaresFit* fit) {
  return encodePtmOrEstimate(tile, options, parent, predictor, coder, scratch, fit, nullptr);
}

Result<void> recordPtm(const ImageView& tile, const ParentTexels* parent, Predictor predictor,
                       PtmCoder coder, CodecScratch* scratch, PtmLeastSquaresFit* fit,
                       PtmRecording& recording) {
  if (!isRansCoder(coder))
    return fail(ErrorCode::kInvalidArgument, "ptm: only the rANS coders' walks are recorded");
  TESSERA_TRY(
      encodePtmOrEstimate(tile, {}, parent, predictor, coder, scratch, fit, nullptr, &recording));
  return {};
}

size_t estimateRecordedPtm(const PtmRecording& recording, PtmCoder coder,
                           std::vector<uint8_t>* models) {
  std::vector<uint8_t> chosen;
  std::vector<uint8_t>& params = models != nullptr ? *models : chosen;
  const double bits =
      rans::chooseModels(familyOf(coder), recording.symbols, recording.symbol_contexts,
                         recording.channels, recording.contexts, params);
  return recording.header.size() + params.size() + size_t(bits / 8) + 4 * recording.channels;
}

std::vector<uint8_t> encodeRecordedPtm(const PtmRecording& recording, PtmCoder coder,
                                       CodecScratch* scratch, const std::vector<uint8_t>* models) {
  ScratchRef state(scratch);
  std::vector<uint8_t> chosen;
  if (models == nullptr) {
    rans::chooseModels(familyOf(coder), recording.symbols, recording.symbol_contexts,
                       recording.channels, recording.contexts, chosen);
    models = &chosen;
  }
  std::vector<uint8_t> payload = recording.header;
  payload[1] = uint8_t(coder);
  payload.insert(payload.end(), models->begin(), models->end());
  rans::encode(familyOf(coder), recording.symbols, recording.symbol_contexts, recording.channels,
               recording.contexts, *models, state->compressed, payload);
  return payload;
}

Result<size_t> estimatePtmBytes(const ImageView& tile, const EncodeOptions& options,
                                const ParentTexels* parent, Predictor predictor, PtmCoder coder,
                                CodecScratch* scratch, PtmLeastSquaresFit* fit) {
  size_t bytes = 0;
  TESSERA_TRY(encodePtmOrEstimate(tile, options, parent, predictor, coder, scratch, fit, &bytes));
  return bytes;
}

Result<void> decodePtm(std::span<const uint8_t> payload, Image& out, const ParentTexels* parent,
                       CodecScratch* scratch) {
  ScratchRef state(scratch);
  const uint32_t width = out.width_px, height = out.height_px, channels = out.channels;
  if (payload.size() < kHeaderBytes)
    return fail(ErrorCode::kCorrupt,
                fmt::format("ptm payload: {} bytes, shorter than its header", payload.size()));
  if (payload[0] > uint8_t(Predictor::kLeastSquares))
    return fail(ErrorCode::kCorrupt, fmt::format("ptm payload: unknown predictor {}", payload[0]));
  if (payload[1] > uint8_t(PtmCoder::kRansParentErrors))
    return fail(ErrorCode::kCorrupt,
                fmt::format("ptm payload: unknown entropy coder {}", payload[1]));
  const Predictor predictor = Predictor(payload[0]);
  const PtmCoder coder = PtmCoder(payload[1]);
  const bool has_parent = predictor != Predictor::kRoot;
  if (has_parent && parent == nullptr)
    return fail(ErrorCode::kCorrupt,
                "ptm payload: coded against a parent tile, but the tile has none (coarsest "
                "level)");
  AxisMap columns, rows;
  if (has_parent)
    TESSERA_TRY(mapParent(parent->texels, *parent, width, height, channels, columns, rows));
  if (predictor == Predictor::kParentCorrected || predictor == Predictor::kLeastSquares)
    upsample(channels, parent->texels, columns, rows, state->upsampled, state->detail);
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
  const Walk walk{out.texels.data(),
                  width,
                  height,
                  has_parent ? &parent->texels : nullptr,
                  &columns,
                  &rows,
                  state->upsampled.data(),
                  state->detail.data(),
                  errorPlane(coder, width, height, *state),
                  ls_weights,
                  nullptr};

  const uint32_t contexts = has_parent ? kParentContexts : kRootContexts;
  using rans::FamilyId;
  switch (coder) {
    case PtmCoder::kZstd: break;
    case PtmCoder::kRans:
      return decodeRans<false, FamilyId::kGeometric12>(payload, body_at, predictor, channels,
                                                       contexts, walk);
    case PtmCoder::kRansChained:
      return decodeRans<true, FamilyId::kGeometric12>(payload, body_at, predictor, channels,
                                                      contexts, walk);
    case PtmCoder::kRansMixture:
      return decodeRans<false, FamilyId::kMixture15>(payload, body_at, predictor, channels,
                                                     contexts, walk);
    case PtmCoder::kRansMixtureChained:
      return decodeRans<true, FamilyId::kMixture15>(payload, body_at, predictor, channels, contexts,
                                                    walk);
    case PtmCoder::kRansMixtureChainedErrors:
      return decodeRans<true, FamilyId::kMixture15, true>(payload, body_at, predictor, channels,
                                                          contexts, walk);
    case PtmCoder::kRansParentErrors:
      return decodeRans<true, FamilyId::kMixture15, true, true>(payload, body_at, predictor,
                                                                channels, contexts, walk);
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
                                    name.c_str(), *state));
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
