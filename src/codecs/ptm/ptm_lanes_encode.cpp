// ptm's lane coder, the encoder (ptm_lanes.h): the symbols a coder-1 walk recorded in raster
// order, coded in the lanes' order, and the green-led contexts.
#include <algorithm>

#include "format/byte_io.h"
#include "ptm/ptm_lanes.h"

namespace tessera::detail::ptm::lanes {

void leadByGreen(std::span<const uint8_t> symbols, std::span<uint8_t> contexts, uint32_t channels) {
  for (size_t at = 0; at + channels <= contexts.size(); at += channels) {
    // A derived texel keeps its contexts: every channel of it is a remainder.
    if (contexts[at + kGreenChannel] >= kCodedContexts) continue;
    const uint32_t context = contexts[at + kGreenChannel];
    const uint32_t led =
        context / kActivityClasses * kActivityClasses +
        greenLedClass(context % kActivityClasses, symbols[at + kGreenChannel] == 0);
    for (uint32_t c = 0; c < channels; ++c)
      if (followsGreen(c)) contexts[at + c] = uint8_t(led);
  }
}

void encode(std::span<const uint8_t> symbols, std::span<const uint8_t> contexts, uint32_t width,
            uint32_t height, uint32_t channels, uint32_t contexts_per_channel,
            std::span<const rans::Model* const> context_models, std::vector<uint8_t>& out) {
  // Escape bytes in decoding order; words in reverse (rANS codes backwards), per channel.
  std::vector<uint8_t> escapes[4];
  std::vector<uint16_t> words[4];
  uint32_t states[4][kLanes];
  for (auto& channel : states)
    for (uint32_t& state : channel) state = kLower;
  const uint32_t steps = stepsPerBand(width);
  for (uint32_t y0 = 0; y0 < height; y0 += kLanes) {
    const uint32_t rows = std::min(kLanes, height - y0);
    for (uint32_t t = 0; t < steps; ++t)
      for (uint32_t k = 0; k < rows; ++k) {
        if (t < 2 * k || t - 2 * k >= width) continue;
        const size_t at = (size_t(y0 + k) * width + (t - 2 * k)) * channels;
        for (uint32_t c = 0; c < channels; ++c) {
          const uint32_t code = rans::zigzag(symbols[at + c]);
          if (code >= rans::kEscape) escapes[c].push_back(uint8_t(code));
        }
      }
  }
  const uint32_t bands = (height + kLanes - 1) / kLanes;
  for (uint32_t band = bands; band-- > 0;) {
    const uint32_t y0 = band * kLanes;
    const uint32_t rows = std::min(kLanes, height - y0);
    for (uint32_t t = steps; t-- > 0;)
      for (uint32_t k = rows; k-- > 0;) {
        if (t < 2 * k || t - 2 * k >= width) continue;
        const size_t at = (size_t(y0 + k) * width + (t - 2 * k)) * channels;
        for (uint32_t c = 0; c < channels; ++c) {
          const uint32_t symbol = std::min(rans::zigzag(symbols[at + c]), rans::kEscape);
          const rans::Model& model = *context_models[c * contexts_per_channel + contexts[at + c]];
          const uint32_t freq = model.freq[symbol];
          uint32_t& x = states[c][k];
          // x stays below 2^32 after coding: x < freq * 2^20 before it.
          if (x >= (freq << (32 - kScaleBits))) {
            words[c].push_back(uint16_t(x));
            x >>= 16;
          }
          x = ((x / freq) << kScaleBits) + x % freq + model.start[symbol];
        }
      }
  }
  for (uint32_t c = 0; c < channels; ++c)
    for (uint32_t k = 0; k < kLanes; ++k) appendU32(out, states[c][k]);
  for (uint32_t c = 0; c < channels; ++c) {
    appendU32(out, uint32_t(words[c].size() * 2));
    appendU32(out, uint32_t(escapes[c].size()));
  }
  for (uint32_t c = 0; c < channels; ++c) {
    for (size_t i = words[c].size(); i-- > 0;) {
      out.push_back(uint8_t(words[c][i]));
      out.push_back(uint8_t(words[c][i] >> 8));
    }
    out.insert(out.end(), escapes[c].begin(), escapes[c].end());
  }
}

}  // namespace tessera::detail::ptm::lanes
