// ptm's rANS model families and explicit tables, the decoder's half (ptm_rans.h).
#include "ptm/ptm_rans.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <iterator>
#include <memory>

namespace tessera::detail::rans {

namespace {

// Within a kind, model k's mean grows by 1.148x per step from 0.01 (flat areas) to about 60
// (noise), in Q16; family 2 takes every second mean. Family 1's kinds: geometric in the zigzag
// code, or in |residual| with the weight of 0 as is, doubled or halved. Family 2's weight
// |e| = k by theta^k + share phi^k with phi = theta^(1/4), a heavier tail for contexts that mix
// quiet and busy texels, at 15 bits, so that a flat context's zeros cost less than family 1's
// floor of one slot in 4096 for each other symbol allows (docs/codecs.md).
constexpr uint64_t kFirstMeanQ16 = 655;
constexpr uint64_t kMeanStepQ16 = 75235;

struct Kind {
  int share_shift;        ///< family 2: the heavy geometric's share is 2^-shift; 0: none
  int zero_weight_shift;  ///< the weight of symbol 0 is multiplied by 2^shift
  bool symmetric;         ///< geometric in |residual| (false: in the zigzag code)
};
constexpr Kind kKinds[] = {{0, 0, false}, {0, 0, true}, {0, 1, true}, {0, -1, true}};
constexpr Kind kMixtureKinds[] = {{0, 0, false}, {0, 0, true}, {5, 0, true}, {3, 0, true},
                                  {1, 0, true},  {0, 1, true}, {3, 1, true}, {0, -1, true}};
static_assert(std::size(kKinds) * meansPerKind(FamilyId::kGeometric12) == kModelCount);
static_assert(std::size(kMixtureKinds) * meansPerKind(FamilyId::kMixture15) == kModelCount);

uint64_t shiftedZero(uint64_t weight, int shift) {
  return shift >= 0 ? weight << shift : weight >> -shift;
}

// The frequencies, the decoder's buckets, and with `costs` the encoder's cost_bits.
void quantise(const uint64_t (&weight)[kAlphabet], uint32_t scale_bits, Model& model, bool costs) {
  const uint32_t scale = 1u << scale_bits;
  frequencies(weight, scale_bits, model.freq);
  const uint32_t bucket_slots = scale >> kBucketBits;
  uint32_t start = 0;
  for (uint32_t s = 0; s < kAlphabet; ++s) {
    model.start[s] = uint16_t(start);
    model.entry[s] = start | uint32_t(model.freq[s]) << 16;
    // The buckets whose first slot lies in this symbol's range; the last is shared where the
    // symbol ends inside it.
    const uint32_t end = start + model.freq[s];
    const uint32_t first = (start + bucket_slots - 1) / bucket_slots;
    const uint32_t last = std::min((end + bucket_slots - 1) / bucket_slots, kBuckets);
    if (first < last) {
      std::memset(model.bucket_symbol + first, int(s), last - first);
      if (last * bucket_slots > end) model.bucket_symbol[last - 1] |= kSharedBucket;
    }
    start = end;
    if (costs) model.cost_bits[s] = float(symbolBits(scale_bits, model.freq[s], s));
  }
  model.entry[kAlphabet] = scale;
}

// theta, the ratio of successive weights of a geometric distribution of mean mean_q16, Q16.
uint64_t ratioOfMean(uint64_t mean_q16) {
  return (mean_q16 << 16) / (65536 + mean_q16);
}

void buildGeometric(uint64_t mean_q16, Kind kind, Model& model) {
  const uint64_t theta_q16 = ratioOfMean(mean_q16);
  uint64_t weight[kAlphabet];
  uint64_t w = uint64_t(1) << 40;
  for (uint32_t z = 0; z < kEscape; ++z) {
    weight[z] = z == 0 ? shiftedZero(w, kind.zero_weight_shift) : w;
    // Symmetric: codes 2k-1 and 2k (residuals -k and +k) share one weight.
    if (!kind.symmetric || (z & 1) == 0) w = (w * theta_q16) >> 16;
  }
  // The escape carries the whole tail z >= 63, two codes per step for the symmetric kinds.
  weight[kEscape] = ((kind.symmetric ? 2 * w : w) << 16) / (65536 - theta_q16);
  quantise(weight, 12, model, true);
}

uint64_t isqrt(uint64_t value) {
  uint64_t root = 0;
  for (uint64_t bit = uint64_t(1) << 62; bit != 0; bit >>= 2) {
    if (value >= root + bit) {
      value -= root + bit;
      root = (root >> 1) + bit;
    } else {
      root >>= 1;
    }
  }
  return root;
}

void buildMixture(uint64_t mean_q16, Kind kind, Model& model) {
  const uint64_t theta_q16 = ratioOfMean(mean_q16);
  const uint64_t phi_q16 = isqrt(isqrt(theta_q16 << 16) << 16);
  // 2^36: the escape's sum of up to 193 weights, times the scale, stays within 64 bits.
  uint64_t light = uint64_t(1) << 36;
  uint64_t heavy = kind.share_shift == 0 ? 0 : light >> kind.share_shift;
  uint64_t weight[kAlphabet] = {};
  for (uint32_t z = 0; z < 256; ++z) {
    const uint64_t w = light + heavy;
    if (z == 0)
      weight[z] = shiftedZero(w, kind.zero_weight_shift);
    else
      weight[std::min(z, kEscape)] += w;  // the escape sums codes 63..255
    if (!kind.symmetric || (z & 1) == 0) {
      light = (light * theta_q16) >> 16;
      heavy = (heavy * phi_q16) >> 16;
    }
  }
  quantise(weight, 15, model, true);
}

std::unique_ptr<Model[]> buildFamily(FamilyId id) {
  auto family = std::make_unique<Model[]>(kModelCount);
  const uint32_t per_kind = meansPerKind(id);
  uint64_t mean_q16 = kFirstMeanQ16;
  for (uint32_t k = 0; k < meansPerKind(FamilyId::kGeometric12); ++k) {
    if (id == FamilyId::kGeometric12) {
      for (size_t kind = 0; kind < std::size(kKinds); ++kind)
        buildGeometric(mean_q16, kKinds[kind], family[kind * per_kind + k]);
    } else if (k % 2 == 0) {
      for (size_t kind = 0; kind < std::size(kMixtureKinds); ++kind)
        buildMixture(mean_q16, kMixtureKinds[kind], family[kind * per_kind + k / 2]);
    }
    mean_q16 = (mean_q16 * kMeanStepQ16) >> 16;
  }
  return family;
}

// 256 x 2^(k / 4): a table level's weight is one of these shifted by (q - 1) / 4.
constexpr uint64_t kLevelMantissa[4] = {256, 304, 362, 431};

}  // namespace

void frequencies(const uint64_t (&weight)[kAlphabet], uint32_t scale_bits,
                 uint16_t (&freq)[kAlphabet]) {
  const uint32_t scale = 1u << scale_bits;
  uint64_t total = 0;
  for (uint64_t w : weight) total += w;
  uint32_t sum = 0, largest = 0;
  for (uint32_t s = 0; s < kAlphabet; ++s) {
    const uint64_t f = (weight[s] * scale) / total;
    freq[s] = uint16_t(f == 0 ? 1 : f);
    sum += freq[s];
    if (freq[s] > freq[largest]) largest = s;
  }
  // Flooring loses at most kAlphabet, raising zeros to 1 adds at most kAlphabet, and the
  // largest frequency is at least scale / kAlphabet: it stays positive.
  freq[largest] = uint16_t(int(freq[largest]) + int(scale) - int(sum));
}

double symbolBits(uint32_t scale_bits, uint16_t freq, uint32_t symbol) {
  return double(scale_bits) - std::log2(double(freq)) + (symbol == kEscape ? 8.0 : 0.0);
}

void tableWeights(const uint8_t* levels, uint32_t count, uint64_t (&weight)[kAlphabet]) {
  for (uint32_t s = 0; s < kAlphabet; ++s)
    weight[s] = s < count && levels[s] != 0
                    ? kLevelMantissa[(levels[s] - 1u) & 3u] << ((levels[s] - 1u) >> 2)
                    : 0;
}

const Model* models(FamilyId family) {
  static const std::unique_ptr<Model[]> geometric = buildFamily(FamilyId::kGeometric12);
  static const std::unique_ptr<Model[]> mixture = buildFamily(FamilyId::kMixture15);
  return family == FamilyId::kGeometric12 ? geometric.get() : mixture.get();
}

void buildTableModel(const uint8_t* levels, uint32_t count, uint32_t scale_bits, Model& model,
                     bool costs) {
  uint64_t weight[kAlphabet];
  tableWeights(levels, count, weight);
  quantise(weight, scale_bits, model, costs);
}

size_t readTables(std::span<const uint8_t> bytes, uint32_t context_count, uint32_t scale_bits,
                  std::vector<Model>& models, std::span<const Model*> context_models) {
  const size_t bitmap_bytes = (size_t(context_count) + 7) / 8;
  if (bytes.size() < bitmap_bytes) return 0;
  if (context_count % 8 != 0 && (bytes[bitmap_bytes - 1] >> (context_count % 8)) != 0) return 0;
  uint32_t flagged = 0;
  for (uint32_t context = 0; context < context_count; ++context)
    flagged += (bytes[context / 8] >> (context % 8)) & 1u;
  // An encoder that chose no table sends no section.
  if (flagged == 0) return 0;
  models.resize(flagged);
  size_t position = bitmap_bytes;
  uint32_t table = 0;
  uint8_t levels[kAlphabet];
  for (uint32_t context = 0; context < context_count; ++context) {
    if (((bytes[context / 8] >> (context % 8)) & 1u) == 0) continue;
    if (position >= bytes.size()) return 0;
    const uint32_t symbols = bytes[position];
    if (symbols == 0 || symbols > kAlphabet || bytes.size() - position < tableBytes(symbols))
      return 0;
    uint32_t acc = 0, acc_bits = 0, any = 0;
    size_t next = position + 1;
    for (uint32_t s = 0; s < symbols; ++s) {
      if (acc_bits < kTableLevelBits) {
        acc |= uint32_t(bytes[next++]) << acc_bits;
        acc_bits += 8;
      }
      levels[s] = uint8_t(acc & (kTableLevels - 1));
      any |= levels[s];
      acc >>= kTableLevelBits;
      acc_bits -= kTableLevelBits;
    }
    if (acc != 0 || any == 0) return 0;
    position += tableBytes(symbols);
    buildTableModel(levels, symbols, scale_bits, models[table], false);
    context_models[context] = &models[table++];
  }
  return position;
}

}  // namespace tessera::detail::rans
