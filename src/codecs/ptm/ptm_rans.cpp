#include "ptm/ptm_rans.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <iterator>
#include <memory>

namespace tessera::detail::rans {

namespace {

// Family 1: four kinds of 64 models each; within a kind, model k's mean grows by 1.148x per
// step from 0.01 (flat areas, where nearly every residual is 0) to about 60 (noise), in Q16.
// Kind 0 is geometric in the zigzag code, which makes +e much less likely than -e when the mean
// is small; kind 1 is geometric in |e| (two-sided, symmetric), and kinds 2 and 3 are kind 1
// with the weight of 0 doubled or halved. Kind 0 alone cost 20 % more than each context's own
// symbol statistics on the codec study's photograph; the four kinds together cost 8 % more.
//
// Family 2: eight kinds of 32 models each, the means every second one of family 1's, with
// 15-bit probabilities, so that a flat context's zeros cost less than family 1's floor of one
// slot in 4096 for each of the 63 other symbols allows. A kind weights |e| = k by
// theta^k + share * phi^k with phi = theta^(1/4): the tail of a context that mixes quiet and
// busy texels is heavier than one geometric's. Kind 0 is family 1's kind 0 (share 0, in the
// zigzag code); kinds 1-4 have shares 0, 1/32, 1/8 and 1/2; kinds 5 and 6 shares 0 and 1/8
// with symbol 0's weight doubled, kind 7 share 0 with it halved. On four level-0 tiles of the
// codec study's photograph (neighbour median, chained contexts) the symbols cost 5 % fewer
// bits than with family 1, and 1-2 % fewer with the other predictors; the scale alone was
// about 3 %.
constexpr uint64_t kFirstMeanQ16 = 655;
constexpr uint64_t kMeanStepQ16 = 75235;
constexpr uint32_t kMeansPerKind = 64;
constexpr uint32_t kCoarseStep = 8;
constexpr uint32_t kMixtureMeansPerKind = 32;
constexpr uint32_t kMixtureCoarseStep = 4;

struct Kind {
  bool symmetric;
  int zero_weight_shift;  ///< the weight of symbol 0 is multiplied by 2^shift
};
constexpr Kind kKinds[] = {{false, 0}, {true, 0}, {true, 1}, {true, -1}};
static_assert(std::size(kKinds) * kMeansPerKind == kModelCount);

struct MixtureKind {
  int share_shift;        ///< the heavy geometric's share is 2^-shift; 0: none
  int zero_weight_shift;  ///< the weight of symbol 0 is multiplied by 2^shift
  bool symmetric = true;  ///< false: geometric in the zigzag code, as family 1's kind 0
};
constexpr MixtureKind kMixtureKinds[] = {{0, 0, false}, {0, 0}, {5, 0}, {3, 0},
                                         {1, 0},        {0, 1}, {3, 1}, {0, -1}};
static_assert(std::size(kMixtureKinds) * kMixtureMeansPerKind == kModelCount);

// Frequencies summing to 2^scale_bits from the symbols' weights, each at least 1.
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
  // Flooring loses at most kAlphabet; raising zeros to 1 adds at most kAlphabet, and the largest
  // frequency is at least scale / kAlphabet, so it stays positive.
  freq[largest] = uint16_t(int(freq[largest]) + int(scale) - int(sum));
}

// What a symbol of frequency `freq` at `scale_bits` costs, in bits: the escape brings its 8
// uniform bits.
double symbolBits(uint32_t scale_bits, uint16_t freq, uint32_t symbol) {
  return double(scale_bits) - std::log2(double(freq)) + (symbol == kEscape ? 8.0 : 0.0);
}

// frequencies(), the decoder's tables, and with `costs` the encoder's cost_bits (64 logarithms,
// which decoders building a payload's tables skip).
void quantise(const uint64_t (&weight)[kAlphabet], uint32_t scale_bits, Model& model,
              bool costs = true) {
  const uint32_t scale = 1u << scale_bits;
  frequencies(weight, scale_bits, model.freq);
  const uint32_t bucket_slots = scale >> kBucketBits;
  uint32_t start = 0;
  for (uint32_t s = 0; s < kAlphabet; ++s) {
    model.start[s] = uint16_t(start);
    model.entry[s] = start | uint32_t(model.freq[s]) << 16;
    // The buckets whose first slot lies in this symbol's range; the last is shared where the
    // symbol ends inside it. One fill per symbol: decoders build a payload's tables per tile.
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

// theta, the ratio of successive weights of a geometric distribution with mean mean_q16, Q16.
uint64_t ratioOfMean(uint64_t mean_q16) {
  return (mean_q16 << 16) / (65536 + mean_q16);
}

void buildGeometric(uint64_t mean_q16, Kind kind, Model& model) {
  const uint64_t theta_q16 = ratioOfMean(mean_q16);
  uint64_t weight[kAlphabet];
  uint64_t w = uint64_t(1) << 40;
  for (uint32_t z = 0; z < kEscape; ++z) {
    weight[z] = w;
    if (z == 0)
      weight[z] =
          kind.zero_weight_shift >= 0 ? w << kind.zero_weight_shift : w >> -kind.zero_weight_shift;
    // Symmetric: codes 2k-1 and 2k (residuals -k and +k) share one weight.
    if (!kind.symmetric || (z & 1) == 0) w = (w * theta_q16) >> 16;
  }
  // The escape carries the whole tail, z >= 63, of the distribution: for the symmetric kinds
  // two codes per step of the geometric series.
  weight[kEscape] = ((kind.symmetric ? 2 * w : w) << 16) / (65536 - theta_q16);
  quantise(weight, 12, model);
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

void buildMixture(uint64_t mean_q16, MixtureKind kind, Model& model) {
  const uint64_t theta_q16 = ratioOfMean(mean_q16);
  const uint64_t phi_q16 = isqrt(isqrt(theta_q16 << 16) << 16);
  // 2^36: the escape's sum of up to 193 weights, times the scale, stays within 64 bits.
  uint64_t light = uint64_t(1) << 36;
  uint64_t heavy = kind.share_shift == 0 ? 0 : light >> kind.share_shift;
  uint64_t weight[kAlphabet] = {};
  // Symmetric: codes 2k-1 and 2k (residuals -k and +k) share one weight. The escape sums codes
  // 63..255, the whole tail.
  for (uint32_t z = 0; z < 256; ++z) {
    const uint64_t w = light + heavy;
    if (z == 0)
      weight[z] =
          kind.zero_weight_shift >= 0 ? w << kind.zero_weight_shift : w >> -kind.zero_weight_shift;
    else if (z < kEscape)
      weight[z] = w;
    else
      weight[kEscape] += w;
    if (!kind.symmetric || (z & 1) == 0) {
      light = (light * theta_q16) >> 16;
      heavy = (heavy * phi_q16) >> 16;
    }
  }
  quantise(weight, 15, model);
}

std::unique_ptr<Model[]> buildFamily(FamilyId id) {
  auto family = std::make_unique<Model[]>(kModelCount);
  uint64_t mean_q16 = kFirstMeanQ16;
  for (uint32_t k = 0; k < kMeansPerKind; ++k) {
    if (id == FamilyId::kGeometric12) {
      for (size_t kind = 0; kind < std::size(kKinds); ++kind)
        buildGeometric(mean_q16, kKinds[kind], family[kind * kMeansPerKind + k]);
    } else if (k % 2 == 0) {
      for (size_t kind = 0; kind < std::size(kMixtureKinds); ++kind)
        buildMixture(mean_q16, kMixtureKinds[kind], family[kind * kMixtureMeansPerKind + k / 2]);
    }
    mean_q16 = (mean_q16 * kMeanStepQ16) >> 16;
  }
  return family;
}

// Byte-wise rANS step (as in Giesen's ryg_rans): bytes go out backwards.
template <uint32_t kScaleBits>
inline void put(uint32_t& x, uint32_t start, uint32_t freq, uint8_t*& out) {
  const uint32_t x_max = ((kLower >> kScaleBits) << 8) * freq;
  while (x >= x_max) {
    *--out = uint8_t(x);
    x >>= 8;
  }
  x = ((x / freq) << kScaleBits) + (x % freq) + start;
}

template <uint32_t kScaleBits>
void encodeAt(std::span<const uint8_t> residuals, std::span<const uint8_t> contexts,
              uint32_t channels, uint32_t contexts_per_channel,
              std::span<const Model* const> context_models, std::vector<uint8_t>& work,
              std::vector<uint8_t>& out) {
  // Each symbol emits at most 2 bytes, an escaped one 4; then 4 bytes of state per channel.
  work.resize(residuals.size() * 4 + 16);
  uint8_t* const end = work.data() + work.size();
  uint8_t* cursor = end;
  uint32_t state[4] = {kLower, kLower, kLower, kLower};
  uint32_t channel = uint32_t(residuals.size() % channels);
  for (size_t i = residuals.size(); i-- > 0;) {
    channel = channel == 0 ? channels - 1 : channel - 1;
    const Model& model = *context_models[channel * contexts_per_channel + contexts[i]];
    const uint32_t z = zigzag(residuals[i]);
    uint32_t& x = state[channel];
    if (z >= kEscape) {
      constexpr uint32_t kUniform = (1u << kScaleBits) >> 8;
      put<kScaleBits>(x, z * kUniform, kUniform, cursor);
      put<kScaleBits>(x, model.start[kEscape], model.freq[kEscape], cursor);
    } else {
      put<kScaleBits>(x, model.start[z], model.freq[z], cursor);
    }
  }
  for (uint32_t c = channels; c-- > 0;)
    for (int shift = 24; shift >= 0; shift -= 8) *--cursor = uint8_t(state[c] >> shift);
  out.insert(out.end(), cursor, end);
}

}  // namespace

const Model* models(FamilyId family) {
  static const std::unique_ptr<Model[]> geometric = buildFamily(FamilyId::kGeometric12);
  static const std::unique_ptr<Model[]> mixture = buildFamily(FamilyId::kMixture15);
  return family == FamilyId::kGeometric12 ? geometric.get() : mixture.get();
}

ContextCounts countByContext(std::span<const uint8_t> residuals, std::span<const uint8_t> contexts,
                             uint32_t channels, uint32_t contexts_per_channel) {
  ContextCounts out;
  out.context_count = channels * contexts_per_channel;
  out.counts.assign(size_t(out.context_count) * kAlphabet, 0);
  // A channel counter, not i % channels: a division per symbol cost a third of the encoder.
  uint32_t channel = 0;
  for (size_t i = 0; i < residuals.size(); ++i) {
    const uint32_t z = zigzag(residuals[i]);
    const uint32_t context = channel * contexts_per_channel + contexts[i];
    ++out.counts[size_t(context) * kAlphabet + (z < kEscape ? z : kEscape)];
    if (++channel == channels) channel = 0;
  }
  return out;
}

double chooseModels(FamilyId family_id, const ContextCounts& context_counts,
                    std::vector<uint8_t>& params) {
  const uint32_t context_count = context_counts.context_count;
  const std::vector<uint32_t>& counts = context_counts.counts;
  const Model* family = models(family_id);
  const bool geometric = family_id == FamilyId::kGeometric12;
  const uint32_t means_per_kind = geometric ? kMeansPerKind : kMixtureMeansPerKind;
  const uint32_t coarse_step = geometric ? kCoarseStep : kMixtureCoarseStep;
  params.assign(context_count, 0);
  uint8_t used[kAlphabet];
  double total_bits = 0;
  for (uint32_t context = 0; context < context_count; ++context) {
    const uint32_t* count = &counts[size_t(context) * kAlphabet];
    // A context sees few distinct symbols, so each model is priced over those alone.
    uint32_t used_count = 0;
    double used_weight[kAlphabet];
    for (uint32_t s = 0; s < kAlphabet; ++s)
      if (count[s] != 0) {
        used_weight[used_count] = count[s];
        used[used_count++] = uint8_t(s);
      }
    if (used_count == 0) continue;
    auto bitsOf = [&](uint32_t k) {
      double bits = 0;
      for (uint32_t i = 0; i < used_count; ++i)
        bits += used_weight[i] * double(family[k].cost_bits[used[i]]);
      return bits;
    };
    // Within a kind the cost falls and then rises with the mean, so every coarse_step-th mean
    // and then the neighbours of the best of those find the kind's best.
    double best = -1;
    for (uint32_t kind = 0; kind < kModelCount / means_per_kind; ++kind) {
      const uint32_t first = kind * means_per_kind;
      uint32_t coarse = first;
      double coarse_bits = -1;
      for (uint32_t k = first + coarse_step / 2; k < first + means_per_kind; k += coarse_step) {
        const double bits = bitsOf(k);
        if (coarse_bits < 0 || bits < coarse_bits) {
          coarse_bits = bits;
          coarse = k;
        }
      }
      const uint32_t low = coarse >= first + coarse_step - 1 ? coarse - (coarse_step - 1) : first;
      const uint32_t high = std::min(first + means_per_kind - 1, coarse + coarse_step - 1);
      for (uint32_t k = low; k <= high; ++k) {
        const double bits = k == coarse ? coarse_bits : bitsOf(k);
        if (best < 0 || bits < best) {
          best = bits;
          params[context] = uint8_t(k);
        }
      }
    }
    total_bits += best;
  }
  return total_bits;
}

double shareModels(FamilyId family_id, const ContextCounts& context_counts, double slack,
                   std::vector<uint8_t>& params) {
  const uint32_t context_count = context_counts.context_count;
  const std::vector<uint32_t>& counts = context_counts.counts;
  const Model* family = models(family_id);
  auto bitsUnder = [&](uint32_t context, uint32_t model) {
    const uint32_t* count = &counts[size_t(context) * kAlphabet];
    double bits = 0;
    for (uint32_t s = 0; s < kAlphabet; ++s)
      if (count[s] != 0) bits += count[s] * double(family[model].cost_bits[s]);
    return bits;
  };
  // The used contexts by symbol count, and how many use each model.
  std::vector<std::pair<uint64_t, uint32_t>> by_size;
  uint32_t users[kModelCount] = {};
  for (uint32_t context = 0; context < context_count; ++context) {
    const uint32_t* count = &counts[size_t(context) * kAlphabet];
    uint64_t symbols = 0;
    for (uint32_t s = 0; s < kAlphabet; ++s) symbols += count[s];
    if (symbols == 0) continue;
    by_size.emplace_back(symbols, context);
    ++users[params[context]];
  }
  std::sort(by_size.begin(), by_size.end());
  double total_bits = 0;
  for (const auto& [symbols, context] : by_size) {
    const uint32_t own_model = params[context];
    const double own = bitsUnder(context, own_model);
    double best = own;
    uint32_t best_model = own_model;
    // A model another context shares already stays.
    if (users[own_model] == 1) {
      double cheapest = -1;
      for (uint32_t model = 0; model < kModelCount; ++model) {
        if (users[model] == 0 || model == own_model) continue;
        const double bits = bitsUnder(context, model);
        if (cheapest < 0 || bits < cheapest) {
          cheapest = bits;
          best_model = model;
        }
      }
      if (cheapest >= 0 && cheapest <= own * (1 + slack) + 8) {
        best = cheapest;
        --users[own_model];
        ++users[best_model];
        params[context] = uint8_t(best_model);
      }
    }
    total_bits += best;
  }
  return total_bits;
}

void encode(FamilyId family, std::span<const uint8_t> residuals, std::span<const uint8_t> contexts,
            uint32_t channels, uint32_t contexts_per_channel,
            std::span<const Model* const> context_models, std::vector<uint8_t>& work,
            std::vector<uint8_t>& out) {
  if (family == FamilyId::kGeometric12)
    encodeAt<scaleBits(FamilyId::kGeometric12)>(residuals, contexts, channels, contexts_per_channel,
                                                context_models, work, out);
  else
    encodeAt<scaleBits(FamilyId::kMixture15)>(residuals, contexts, channels, contexts_per_channel,
                                              context_models, work, out);
}

namespace {

// 256 * 2^(k / 4): a table level's weight is one of these shifted by (q - 1) / 4.
constexpr uint64_t kLevelMantissa[4] = {256, 304, 362, 431};

// The level that stands for a frequency `f` of the family's scale: 4 log2 f, rounded, plus 1.
uint8_t levelOf(double f) {
  return uint8_t(
      std::clamp(std::lround(4 * std::log2(std::max(1.0, f))), 0L, long(kTableLevels) - 2) + 1);
}

// A table's weights: level q > 0 stands for 256 x 2^((q - 1) / 4), symbols from `count` on 0.
void tableWeights(const uint8_t* levels, uint32_t count, uint64_t (&weight)[kAlphabet]) {
  for (uint32_t s = 0; s < kAlphabet; ++s)
    weight[s] = s < count && levels[s] != 0
                    ? kLevelMantissa[(levels[s] - 1u) & 3u] << ((levels[s] - 1u) >> 2)
                    : 0;
}

}  // namespace

void buildTableModel(const uint8_t* levels, uint32_t count, uint32_t scale_bits, Model& model,
                     bool costs) {
  uint64_t weight[kAlphabet];
  tableWeights(levels, count, weight);
  quantise(weight, scale_bits, model, costs);
}

bool chooseTables(FamilyId family_id, const ContextCounts& context_counts,
                  std::span<const uint8_t> params, Tables& tables, double min_gain_bytes) {
  const uint32_t context_count = context_counts.context_count;
  const std::vector<uint32_t>& counts = context_counts.counts;
  const uint32_t scale_bits = scaleBits(family_id);
  const Model* family = models(family_id);
  tables = {};
  tables.context_models.resize(context_count);
  std::vector<uint8_t> levels(size_t(context_count) * kAlphabet, 0);
  std::vector<uint32_t> table_count(context_count, 0);
  std::vector<uint32_t> flagged;
  double family_bits = 0, saved_bits = 0;
  uint64_t weight[kAlphabet];
  uint16_t freq[kAlphabet];
  for (uint32_t context = 0; context < context_count; ++context) {
    const uint32_t* count = &counts[size_t(context) * kAlphabet];
    const Model& model = family[params[context]];
    tables.context_models[context] = &model;
    double total = 0, bits = 0;
    uint32_t symbols = 0;
    for (uint32_t s = 0; s < kAlphabet; ++s) {
      if (count[s] == 0) continue;
      total += count[s];
      bits += count[s] * double(model.cost_bits[s]);
      symbols = s + 1;
    }
    family_bits += bits;
    if (symbols == 0) continue;
    uint8_t* level = &levels[size_t(context) * kAlphabet];
    for (uint32_t s = 0; s < symbols; ++s)
      if (count[s] != 0) level[s] = levelOf(count[s] * double(1u << scale_bits) / total);
    // The candidate's frequencies alone price it; the decoder's tables are built for the chosen.
    tableWeights(level, symbols, weight);
    frequencies(weight, scale_bits, freq);
    double table_bits = 0;
    for (uint32_t s = 0; s < symbols; ++s)
      if (count[s] != 0) table_bits += count[s] * symbolBits(scale_bits, freq[s], s);
    const double gain = bits - table_bits - 8.0 * double(tableBytes(symbols));
    if (gain <= 8.0 * min_gain_bytes) continue;
    saved_bits += gain;
    table_count[context] = symbols;
    flagged.push_back(context);
  }
  const size_t bitmap_bytes = (context_count + 7) / 8;
  if (flagged.empty() || saved_bits <= 8.0 * double(bitmap_bytes)) {
    tables.bits = family_bits;
    return false;
  }
  tables.section.assign(bitmap_bytes, 0);
  tables.models.resize(flagged.size());
  tables.bits = family_bits;
  for (size_t t = 0; t < flagged.size(); ++t) {
    const uint32_t context = flagged[t];
    const uint32_t symbols = table_count[context];
    const uint8_t* level = &levels[size_t(context) * kAlphabet];
    tables.section[context / 8] |= uint8_t(1u << (context % 8));
    tables.section.push_back(uint8_t(symbols));
    uint32_t acc = 0, acc_bits = 0;
    for (uint32_t s = 0; s < symbols; ++s) {
      acc |= uint32_t(level[s]) << acc_bits;
      acc_bits += kTableLevelBits;
      while (acc_bits >= 8) {
        tables.section.push_back(uint8_t(acc));
        acc >>= 8;
        acc_bits -= 8;
      }
    }
    if (acc_bits > 0) tables.section.push_back(uint8_t(acc));
    Model& model = tables.models[t];
    buildTableModel(level, symbols, scale_bits, model);
    const uint32_t* count = &counts[size_t(context) * kAlphabet];
    for (uint32_t s = 0; s < symbols; ++s)
      tables.bits += count[s] * (double(model.cost_bits[s]) -
                                 double(tables.context_models[context]->cost_bits[s]));
    tables.context_models[context] = &model;
  }
  return true;
}

size_t readTables(std::span<const uint8_t> bytes, uint32_t context_count, uint32_t scale_bits,
                  std::vector<Model>& models, std::span<const Model*> context_models) {
  const size_t bitmap_bytes = (size_t(context_count) + 7) / 8;
  if (bytes.size() < bitmap_bytes) return 0;
  // Bits past the last context are zero, and at least one context has a table: an encoder
  // that chose none sends no section.
  if (context_count % 8 != 0 && (bytes[bitmap_bytes - 1] >> (context_count % 8)) != 0) return 0;
  uint32_t flagged = 0;
  for (uint32_t context = 0; context < context_count; ++context)
    flagged += (bytes[context / 8] >> (context % 8)) & 1u;
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
    // Padding bits are zero, and some symbol has a weight (a model needs one).
    if (acc != 0 || any == 0) return 0;
    position += tableBytes(symbols);
    buildTableModel(levels, symbols, scale_bits, models[table], false);
    context_models[context] = &models[table];
    ++table;
  }
  return position;
}

}  // namespace tessera::detail::rans
