// 2x2 box averaging of 16-bit and float rows; the 8-bit paths are in downsample.cpp.
#include <algorithm>
#include <cmath>
#include <cstring>

#include "builder/downsample.h"

namespace tessera::detail {

namespace {

template <class Sample>
Sample load(const uint8_t* texel, uint32_t channel) {
  Sample value;
  std::memcpy(&value, texel + channel * sizeof(Sample), sizeof(Sample));
  return value;
}

template <class Sample>
void store(uint8_t* texel, uint32_t channel, Sample value) {
  std::memcpy(texel + channel * sizeof(Sample), &value, sizeof(Sample));
}

// Mirrors averageGeneral of the 8-bit path: colour weighted by alpha, a fully transparent
// block all zero.
void averageU16(const uint8_t* const texels[4], uint32_t channels, uint8_t* out) {
  const bool has_alpha = channels == 2 || channels == 4;
  const uint32_t colour_channels = has_alpha ? channels - 1 : channels;
  uint64_t alpha_sum = 0;
  if (has_alpha) {
    for (int k = 0; k < 4; ++k) alpha_sum += load<uint16_t>(texels[k], channels - 1);
    store(out, channels - 1, uint16_t((alpha_sum + 2) >> 2));
    if (alpha_sum == 0) {
      for (uint32_t c = 0; c < colour_channels; ++c) store(out, c, uint16_t(0));
      return;
    }
  }
  for (uint32_t c = 0; c < colour_channels; ++c) {
    uint64_t sum = 0;
    for (int k = 0; k < 4; ++k) {
      const uint64_t value = load<uint16_t>(texels[k], c);
      sum += has_alpha ? value * load<uint16_t>(texels[k], channels - 1) : value;
    }
    const uint64_t weight = has_alpha ? alpha_sum : 4;
    store(out, c, uint16_t((sum + weight / 2) / weight));
  }
}

// NaN marks no-data in most float rasters (DEMs, astronomy), so it is left out of the mean
// instead of spreading to every coarser level.
void averageF32(const uint8_t* const texels[4], uint32_t channels, uint8_t* out) {
  for (uint32_t c = 0; c < channels; ++c) {
    double sum = 0;
    int count = 0;
    for (int k = 0; k < 4; ++k) {
      const float value = load<float>(texels[k], c);
      if (std::isnan(value)) continue;
      sum += value;
      ++count;
    }
    if (count == 0) {
      std::memcpy(out + c * 4, texels[0] + c * 4, 4);
      continue;
    }
    store(out, c, float(sum / count));
  }
}

}  // namespace

void downsampleRowPairWide(const uint8_t* top, const uint8_t* bottom, uint32_t width,
                           uint32_t channels, SampleType type, uint8_t* out) {
  const size_t texel_bytes = size_t(channels) * sampleBytes(type);
  const uint32_t out_width = (width + 1) / 2;
  for (uint32_t i = 0; i < out_width; ++i) {
    const uint32_t x0 = 2 * i, x1 = std::min(2 * i + 1, width - 1);
    const uint8_t* const texels[4] = {top + x0 * texel_bytes, top + x1 * texel_bytes,
                                      bottom + x0 * texel_bytes, bottom + x1 * texel_bytes};
    if (type == SampleType::kF32)
      averageF32(texels, channels, out + i * texel_bytes);
    else
      averageU16(texels, channels, out + i * texel_bytes);
  }
}

}  // namespace tessera::detail
