#include "ptm_rans.h"

#include <cmath>
#include <memory>

namespace tessera::detail::rans {

namespace {

// Model k is a geometric distribution of the zigzag residual whose mean grows by 1.148x per
// step from 0.01 (flat areas, where nearly every residual is 0) to about 60 (noise), in Q16.
constexpr uint64_t kFirstMeanQ16 = 655;
constexpr uint64_t kMeanStepQ16 = 75235;

void buildModel(uint64_t mean_q16, Model& model) {
  const uint64_t theta_q16 = (mean_q16 << 16) / (65536 + mean_q16);
  uint64_t weight[kAlphabet];
  uint64_t w = uint64_t(1) << 40;
  uint64_t total = 0;
  for (uint32_t z = 0; z < kEscape; ++z) {
    weight[z] = w;
    total += w;
    w = (w * theta_q16) >> 16;
  }
  // The escape carries the whole tail, z >= 63, of the geometric distribution.
  weight[kEscape] = (w << 16) / (65536 - theta_q16);
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
  for (uint32_t k = 0; k < kModelCount; ++k) {
    buildModel(mean_q16, family[k]);
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

void chooseModels(std::span<const uint8_t> residuals, std::span<const uint8_t> contexts,
                  uint32_t channels, uint32_t contexts_per_channel, std::vector<uint8_t>& params) {
  const uint32_t context_count = channels * contexts_per_channel;
  std::vector<uint32_t> counts(size_t(context_count) * kAlphabet, 0);
  for (size_t i = 0; i < residuals.size(); ++i) {
    const uint32_t z = zigzag(residuals[i]);
    const uint32_t context = uint32_t(i % channels) * contexts_per_channel + contexts[i];
    ++counts[size_t(context) * kAlphabet + (z < kEscape ? z : kEscape)];
  }
  const Model* family = models();
  params.assign(context_count, 0);
  for (uint32_t context = 0; context < context_count; ++context) {
    const uint32_t* count = &counts[size_t(context) * kAlphabet];
    double best = -1;
    for (uint32_t k = 0; k < kModelCount; ++k) {
      double bits = 0;
      for (uint32_t s = 0; s < kAlphabet; ++s) bits += count[s] * double(family[k].cost_bits[s]);
      if (best < 0 || bits < best) {
        best = bits;
        params[context] = uint8_t(k);
      }
    }
  }
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
  for (size_t i = residuals.size(); i-- > 0;) {
    const uint32_t channel = uint32_t(i % channels);
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
  for (uint32_t channel = channels; channel-- > 0;)
    for (int shift = 24; shift >= 0; shift -= 8) *--cursor = uint8_t(state[channel] >> shift);
  out.insert(out.end(), cursor, end);
}

}  // namespace tessera::detail::rans
