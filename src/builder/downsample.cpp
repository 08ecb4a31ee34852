#include "downsample.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

namespace tessera::detail {

namespace {

// sRGB <-> linear with 16-bit linear values, exact to the IEC 61966-2-1 curve at 8 bits.
struct SrgbTables {
  std::array<uint16_t, 256> to_linear;
  std::vector<uint8_t> to_srgb;  // 65536 entries
  SrgbTables() : to_srgb(65536) {
    for (int i = 0; i < 256; ++i) {
      double c = i / 255.0;
      double l = c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
      to_linear[i] = uint16_t(std::lround(l * 65535.0));
    }
    for (int i = 0; i < 65536; ++i) {
      double l = i / 65535.0;
      double c = l <= 0.0031308 ? l * 12.92 : 1.055 * std::pow(l, 1 / 2.4) - 0.055;
      to_srgb[i] = uint8_t(std::lround(std::fmin(std::fmax(c, 0.0), 1.0) * 255.0));
    }
  }
};

const SrgbTables& srgbTables() {
  static const SrgbTables tables;
  return tables;
}

template <uint32_t kChannels>
void averagePlain(const uint8_t* top, const uint8_t* bottom, uint32_t width, uint8_t* out) {
  uint32_t pairs = width / 2;
  for (uint32_t i = 0; i < pairs; ++i) {
    const uint8_t* a = top + 2 * i * kChannels;
    const uint8_t* b = bottom + 2 * i * kChannels;
    for (uint32_t c = 0; c < kChannels; ++c)
      out[i * kChannels + c] =
          uint8_t((a[c] + a[c + kChannels] + b[c] + b[c + kChannels] + 2) >> 2);
  }
  if (width & 1) {
    const uint8_t* a = top + (width - 1) * kChannels;
    const uint8_t* b = bottom + (width - 1) * kChannels;
    for (uint32_t c = 0; c < kChannels; ++c)
      out[pairs * kChannels + c] = uint8_t((2 * a[c] + 2 * b[c] + 2) >> 2);
  }
}

template <uint32_t kChannels>
void averageFloor(const uint8_t* top, const uint8_t* bottom, uint32_t width, uint8_t* out) {
  const uint32_t pairs = width / 2;
  for (uint32_t i = 0; i < pairs; ++i) {
    const uint8_t* a = top + 2 * i * kChannels;
    const uint8_t* b = bottom + 2 * i * kChannels;
    for (uint32_t c = 0; c < kChannels; ++c)
      out[i * kChannels + c] = uint8_t((a[c] + a[c + kChannels] + b[c] + b[c + kChannels]) >> 2);
  }
  if (width & 1) {
    const uint8_t* a = top + (width - 1) * kChannels;
    const uint8_t* b = bottom + (width - 1) * kChannels;
    for (uint32_t c = 0; c < kChannels; ++c)
      out[pairs * kChannels + c] = uint8_t((2 * a[c] + 2 * b[c]) >> 2);
  }
}

// The general path: alpha weighting and/or linear light, one output texel at a time.
void averageGeneral(const uint8_t* top, const uint8_t* bottom, uint32_t width, uint32_t channels,
                    bool srgb, uint8_t* out) {
  const SrgbTables* tables = srgb ? &srgbTables() : nullptr;
  bool has_alpha = channels == 2 || channels == 4;
  uint32_t colour_channels = has_alpha ? channels - 1 : channels;
  uint32_t out_width = (width + 1) / 2;
  for (uint32_t i = 0; i < out_width; ++i) {
    uint32_t x0 = 2 * i, x1 = std::min(2 * i + 1, width - 1);
    const uint8_t* texels[4] = {top + x0 * channels, top + x1 * channels, bottom + x0 * channels,
                                bottom + x1 * channels};
    uint8_t* o = out + i * channels;
    uint32_t alpha_sum = 0;
    if (has_alpha) {
      for (const uint8_t* t : texels) alpha_sum += t[channels - 1];
      o[channels - 1] = uint8_t((alpha_sum + 2) >> 2);
      if (alpha_sum == 0) {
        for (uint32_t c = 0; c < colour_channels; ++c) o[c] = 0;
        continue;
      }
    }
    for (uint32_t c = 0; c < colour_channels; ++c) {
      uint64_t sum = 0;
      for (const uint8_t* t : texels) {
        uint64_t value = tables ? tables->to_linear[t[c]] : t[c];
        sum += has_alpha ? value * t[channels - 1] : value;
      }
      uint64_t weight = has_alpha ? alpha_sum : 4;
      uint64_t mean = (sum + weight / 2) / weight;
      o[c] = tables ? tables->to_srgb[mean] : uint8_t(mean);
    }
  }
}

bool allOpaque(const uint8_t* row, uint32_t width, uint32_t channels) {
  for (uint32_t x = 0; x < width; ++x)
    if (row[x * channels + channels - 1] != 255) return false;
  return true;
}

}  // namespace

void downsampleRowPair(const uint8_t* top, const uint8_t* bottom, uint32_t width, uint32_t channels,
                       bool srgb, uint8_t* out) {
  bool has_alpha = channels == 2 || channels == 4;
  // Opaque rows weight every texel equally, so the plain mean is the alpha-weighted mean.
  bool plain = !srgb && (!has_alpha ||
                         (allOpaque(top, width, channels) && allOpaque(bottom, width, channels)));
  if (plain) {
    switch (channels) {
      case 1: return averagePlain<1>(top, bottom, width, out);
      case 2: return averagePlain<2>(top, bottom, width, out);
      case 3: return averagePlain<3>(top, bottom, width, out);
      case 4: return averagePlain<4>(top, bottom, width, out);
    }
  }
  averageGeneral(top, bottom, width, channels, srgb, out);
}

void downsampleRowPairFloor(const uint8_t* top, const uint8_t* bottom, uint32_t width,
                            uint32_t channels, uint8_t* out) {
  switch (channels) {
    case 1: return averageFloor<1>(top, bottom, width, out);
    case 2: return averageFloor<2>(top, bottom, width, out);
    case 3: return averageFloor<3>(top, bottom, width, out);
    default: return averageFloor<4>(top, bottom, width, out);
  }
}

}  // namespace tessera::detail
