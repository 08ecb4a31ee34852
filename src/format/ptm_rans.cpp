#include "ptm_rans.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <memory>

namespace tessera::detail::rans {

namespace {

// Four kinds of 64 models each; within a kind, model k's mean grows by 1.148x per step from
// 0.01 (flat areas, where nearly every residual is 0) to about 60 (noise), in Q16. Kind 0 is
// geometric in the zigzag code, which makes +e much less likely than -e when the mean is small;
// kind 1 is geometric in |e| (two-sided, symmetric), and kinds 2 and 3 are kind 1 with the
// weight of 0 doubled or halved. Kind 0 alone cost 20 % more than each context's own symbol
// statistics on the codec study's photograph; the four kinds together cost 8 % more.
constexpr uint64_t kFirstMeanQ16 = 655;
constexpr uint64_t kMeanStepQ16 = 75235;
constexpr uint32_t kMeansPerKind = 64;
constexpr uint32_t kCoarseStep = 8;

struct Kind {
  bool symmetric;
  int zero_weight_shift;  ///< the weight of symbol 0 is multiplied by 2^shift
};
constexpr Kind kKinds[] = {{false, 0}, {true, 0}, {true, 1}, {true, -1}};
static_assert(std::size(kKinds) * kMeansPerKind == kModelCount);

void buildModel(uint64_t mean_q16, Kind kind, Model& model) {
  const uint64_t theta_q16 = (mean_q16 << 16) / (65536 + mean_q16);
  uint64_t weight[kAlphabet];
  uint64_t w = uint64_t(1) << 40;
  uint64_t total = 0;
  for (uint32_t z = 0; z < kEscape; ++z) {
    weight[z] = w;
    if (z == 0)
      weight[z] =
          kind.zero_weight_shift >= 0 ? w << kind.zero_weight_shift : w >> -kind.zero_weight_shift;
    total += weight[z];
    // Symmetric: codes 2k-1 and 2k (residuals -k and +k) share one weight.
    if (!kind.symmetric || (z & 1) == 0) w = (w * theta_q16) >> 16;
  }
  // The escape carries the whole tail, z >= 63, of the distribution: for the symmetric kinds
  // two codes per step of the geometric series.
  weight[kEscape] = ((kind.symmetric ? 2 * w : w) << 16) / (65536 - theta_q16);
  total += weight[kEscape];
  uint32_t sum = 0, largest = 0;
  for (uint32_t s = 0; s < kAlphabet; ++s) {
    const uint64_t f = (weight[s] * kScale) / total;
    model.freq[s] = uint16_t(f == 0 ? 1 : f);
    sum += model.freq[s];
    if (model.freq[s] > model.freq[largest]) largest = s;
  }
  // Flooring loses at most kAlphabet; raising zeros to 1 adds at most kAlphabet, and the largest
  // frequency is at least kScale / kAlphabet, so it stays positive.
  model.freq[largest] = uint16_t(int(model.freq[largest]) + int(kScale) - int(sum));
  uint32_t start = 0;
  for (uint32_t s = 0; s < kAlphabet; ++s) {
    model.start[s] = uint16_t(start);
    for (uint32_t i = 0; i < model.freq[s]; ++i) model.symbol_of_slot[start + i] = uint8_t(s);
    start += model.freq[s];
    model.cost_bits[s] = float(kScaleBits - std::log2(double(model.freq[s])));
  }
  model.cost_bits[kEscape] += 8;
}

std::unique_ptr<Model[]> buildModels() {
  auto family = std::make_unique<Model[]>(kModelCount);
  uint64_t mean_q16 = kFirstMeanQ16;
  for (uint32_t k = 0; k < kMeansPerKind; ++k) {
    for (size_t kind = 0; kind < std::size(kKinds); ++kind)
      buildModel(mean_q16, kKinds[kind], family[kind * kMeansPerKind + k]);
    mean_q16 = (mean_q16 * kMeanStepQ16) >> 16;
  }
  return family;
}

// Byte-wise rANS step (as in Giesen's ryg_rans): bytes go out backwards.
inline void put(uint32_t& x, uint32_t start, uint32_t freq, uint8_t*& out) {
  const uint32_t x_max = ((kLower >> kScaleBits) << 8) * freq;
  while (x >= x_max) {
    *--out = uint8_t(x);
    x >>= 8;
  }
  x = ((x / freq) << kScaleBits) + (x % freq) + start;
}

}  // namespace

const Model* models() {
  static const std::unique_ptr<Model[]> family = buildModels();
  return family.get();
}

double chooseModels(std::span<const uint8_t> residuals, std::span<const uint8_t> contexts,
                    uint32_t channels, uint32_t contexts_per_channel,
                    std::vector<uint8_t>& params) {
  const uint32_t context_count = channels * contexts_per_channel;
  std::vector<uint32_t> counts(size_t(context_count) * kAlphabet, 0);
  // A channel counter, not i % channels: a division per symbol cost a third of the encoder.
  uint32_t channel = 0;
  for (size_t i = 0; i < residuals.size(); ++i) {
    const uint32_t z = zigzag(residuals[i]);
    const uint32_t context = channel * contexts_per_channel + contexts[i];
    ++counts[size_t(context) * kAlphabet + (z < kEscape ? z : kEscape)];
    if (++channel == channels) channel = 0;
  }
  const Model* family = models();
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
    // Within a kind the cost falls and then rises with the mean, so every eighth mean and then
    // the neighbours of the best of those find the kind's best (a third of the evaluations).
    double best = -1;
    for (uint32_t kind = 0; kind < kModelCount / kMeansPerKind; ++kind) {
      const uint32_t first = kind * kMeansPerKind;
      uint32_t coarse = first;
      double coarse_bits = -1;
      for (uint32_t k = first + kCoarseStep / 2; k < first + kMeansPerKind; k += kCoarseStep) {
        const double bits = bitsOf(k);
        if (coarse_bits < 0 || bits < coarse_bits) {
          coarse_bits = bits;
          coarse = k;
        }
      }
      const uint32_t low = coarse >= first + kCoarseStep - 1 ? coarse - (kCoarseStep - 1) : first;
      const uint32_t high = std::min(first + kMeansPerKind - 1, coarse + kCoarseStep - 1);
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

void encode(std::span<const uint8_t> residuals, std::span<const uint8_t> contexts,
            uint32_t channels, uint32_t contexts_per_channel, std::span<const uint8_t> params,
            std::vector<uint8_t>& work, std::vector<uint8_t>& out) {
  // Each symbol emits at most 2 bytes, an escaped one 4; then 4 bytes of state per channel.
  work.resize(residuals.size() * 4 + 16);
  uint8_t* const end = work.data() + work.size();
  uint8_t* cursor = end;
  uint32_t state[4] = {kLower, kLower, kLower, kLower};
  const Model* family = models();
  uint32_t channel = uint32_t(residuals.size() % channels);
  for (size_t i = residuals.size(); i-- > 0;) {
    channel = channel == 0 ? channels - 1 : channel - 1;
    const Model& model = family[params[channel * contexts_per_channel + contexts[i]]];
    const uint32_t z = zigzag(residuals[i]);
    uint32_t& x = state[channel];
    if (z >= kEscape) {
      constexpr uint32_t kUniform = kScale >> 8;
      put(x, z * kUniform, kUniform, cursor);
      put(x, model.start[kEscape], model.freq[kEscape], cursor);
    } else {
      put(x, model.start[z], model.freq[z], cursor);
    }
  }
  for (uint32_t c = channels; c-- > 0;)
    for (int shift = 24; shift >= 0; shift -= 8) *--cursor = uint8_t(state[c] >> shift);
  out.insert(out.end(), cursor, end);
}

}  // namespace tessera::detail::rans
