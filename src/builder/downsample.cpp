#include "builder/downsample.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#if defined(__x86_64__)
#include <tmmintrin.h>
#endif

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
void averagePlain(const uint8_t* top, const uint8_t* bottom, uint32_t width, uint8_t* out,
                  uint32_t first_pair = 0) {
  uint32_t pairs = width / 2;
  for (uint32_t i = first_pair; i < pairs; ++i) {
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

// Vector kernels for the plain mean (sum + 2) >> 2. Each handles whole blocks of output texels
// and returns how many it wrote; averagePlain finishes the row from there, so the result is
// the scalar rule's bit for bit. SSE2 is part of x86-64; SSSE3 (pshufb, needed to gather RGB
// triplets) is chosen at run time, so the default build needs no -march.
#if defined(__x86_64__)

inline __m128i roundedQuarter(__m128i sum) {
  return _mm_srli_epi16(_mm_add_epi16(sum, _mm_set1_epi16(2)), 2);
}

// Gray: 16 output texels from 32 bytes of each row; a 16-bit lane holds a horizontal pair.
uint32_t averageGraySse2(const uint8_t* top, const uint8_t* bottom, uint32_t pairs, uint8_t* out) {
  const __m128i low_byte = _mm_set1_epi16(0x00FF);
  auto pairSums = [&](const uint8_t* row) {
    __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(row));
    return _mm_add_epi16(_mm_and_si128(v, low_byte), _mm_srli_epi16(v, 8));
  };
  uint32_t i = 0;
  for (; i + 16 <= pairs; i += 16) {
    const uint8_t* t = top + 2 * i;
    const uint8_t* b = bottom + 2 * i;
    __m128i first = roundedQuarter(_mm_add_epi16(pairSums(t), pairSums(b)));
    __m128i second = roundedQuarter(_mm_add_epi16(pairSums(t + 16), pairSums(b + 16)));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + i), _mm_packus_epi16(first, second));
  }
  return i;
}

// RGBA: 4 output texels from 32 bytes of each row; texels 2k and 2k+1 meet in the 64-bit halves.
uint32_t averageRgbaSse2(const uint8_t* top, const uint8_t* bottom, uint32_t pairs, uint8_t* out) {
  const __m128i zero = _mm_setzero_si128();
  // Two output texels (8 lanes) from 16 bytes (4 texels) of each row.
  auto twoTexels = [&](const uint8_t* t, const uint8_t* b) {
    __m128i vt = _mm_loadu_si128(reinterpret_cast<const __m128i*>(t));
    __m128i vb = _mm_loadu_si128(reinterpret_cast<const __m128i*>(b));
    __m128i low = _mm_add_epi16(_mm_unpacklo_epi8(vt, zero), _mm_unpacklo_epi8(vb, zero));
    __m128i high = _mm_add_epi16(_mm_unpackhi_epi8(vt, zero), _mm_unpackhi_epi8(vb, zero));
    return roundedQuarter(
        _mm_add_epi16(_mm_unpacklo_epi64(low, high), _mm_unpackhi_epi64(low, high)));
  };
  uint32_t i = 0;
  for (; i + 4 <= pairs; i += 4) {
    const size_t at = size_t(8) * i;
    __m128i first = twoTexels(top + at, bottom + at);
    __m128i second = twoTexels(top + at + 16, bottom + at + 16);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + 4 * size_t(i)),
                     _mm_packus_epi16(first, second));
  }
  return i;
}

// RGB: 8 output texels from 48 bytes of each row. Adding each byte to the one 3 further on sums
// a texel's channel with its right neighbour's; the sums at bytes 0-2 of every 6 are the
// outputs, gathered with pshufb. The loads reach 3 bytes past the block, hence the bound.
__attribute__((target("ssse3"))) uint32_t averageRgbSsse3(const uint8_t* top, const uint8_t* bottom,
                                                          uint32_t width, uint8_t* out) {
  const __m128i zero = _mm_setzero_si128();
  auto load = [](const uint8_t* p) { return _mm_loadu_si128(reinterpret_cast<const __m128i*>(p)); };
  // Rounded means at the 16 byte positions from `at`.
  auto sixteen = [&](size_t at) {
    __m128i a = load(top + at), b = load(top + at + 3), c = load(bottom + at),
            d = load(bottom + at + 3);
    __m128i low =
        _mm_add_epi16(_mm_add_epi16(_mm_unpacklo_epi8(a, zero), _mm_unpacklo_epi8(b, zero)),
                      _mm_add_epi16(_mm_unpacklo_epi8(c, zero), _mm_unpacklo_epi8(d, zero)));
    __m128i high =
        _mm_add_epi16(_mm_add_epi16(_mm_unpackhi_epi8(a, zero), _mm_unpackhi_epi8(b, zero)),
                      _mm_add_epi16(_mm_unpackhi_epi8(c, zero), _mm_unpackhi_epi8(d, zero)));
    return _mm_packus_epi16(roundedQuarter(low), roundedQuarter(high));
  };
  // Byte positions wanted: 0 1 2, 6 7 8, ... 42 43 44 of the 48; -1 clears a byte.
  const __m128i first_from_0 =
      _mm_setr_epi8(0, 1, 2, 6, 7, 8, 12, 13, 14, -1, -1, -1, -1, -1, -1, -1);
  const __m128i first_from_16 =
      _mm_setr_epi8(-1, -1, -1, -1, -1, -1, -1, -1, -1, 2, 3, 4, 8, 9, 10, 14);
  const __m128i second_from_16 =
      _mm_setr_epi8(15, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1);
  const __m128i second_from_32 =
      _mm_setr_epi8(-1, 0, 4, 5, 6, 10, 11, 12, -1, -1, -1, -1, -1, -1, -1, -1);
  const size_t row_bytes = size_t(width) * 3;
  uint32_t i = 0;
  for (; size_t(6) * i + 51 <= row_bytes; i += 8) {
    const size_t at = size_t(6) * i;
    __m128i r0 = sixteen(at), r1 = sixteen(at + 16), r2 = sixteen(at + 32);
    __m128i first =
        _mm_or_si128(_mm_shuffle_epi8(r0, first_from_0), _mm_shuffle_epi8(r1, first_from_16));
    __m128i second =
        _mm_or_si128(_mm_shuffle_epi8(r1, second_from_16), _mm_shuffle_epi8(r2, second_from_32));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + 3 * size_t(i)), first);
    _mm_storel_epi64(reinterpret_cast<__m128i*>(out + 3 * size_t(i) + 16), second);
  }
  return i;
}

bool hasSsse3() {
  static const bool supported = __builtin_cpu_supports("ssse3") != 0;
  return supported;
}

#endif

// The plain mean through the widest kernel this machine runs, the rest scalar.
template <uint32_t kChannels>
void averagePlainFast(const uint8_t* top, const uint8_t* bottom, uint32_t width, uint8_t* out) {
  uint32_t done = 0;
#if defined(__x86_64__)
  if constexpr (kChannels == 1) done = averageGraySse2(top, bottom, width / 2, out);
  if constexpr (kChannels == 3) done = hasSsse3() ? averageRgbSsse3(top, bottom, width, out) : 0;
  if constexpr (kChannels == 4) done = averageRgbaSse2(top, bottom, width / 2, out);
#endif
  averagePlain<kChannels>(top, bottom, width, out, done);
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

template <bool kVector, uint32_t kChannels>
void averagePlainWith(const uint8_t* top, const uint8_t* bottom, uint32_t width, uint8_t* out) {
  if constexpr (kVector)
    averagePlainFast<kChannels>(top, bottom, width, out);
  else
    averagePlain<kChannels>(top, bottom, width, out);
}

template <bool kVector>
void downsampleRowPairWith(const uint8_t* top, const uint8_t* bottom, uint32_t width,
                           uint32_t channels, bool srgb, uint8_t* out) {
  bool has_alpha = channels == 2 || channels == 4;
  // Opaque rows weight every texel equally, so the plain mean is the alpha-weighted mean.
  bool plain = !srgb && (!has_alpha ||
                         (allOpaque(top, width, channels) && allOpaque(bottom, width, channels)));
  if (plain) {
    switch (channels) {
      case 1: return averagePlainWith<kVector, 1>(top, bottom, width, out);
      case 2: return averagePlain<2>(top, bottom, width, out);  // no vector kernel: rare
      case 3: return averagePlainWith<kVector, 3>(top, bottom, width, out);
      case 4: return averagePlainWith<kVector, 4>(top, bottom, width, out);
    }
  }
  averageGeneral(top, bottom, width, channels, srgb, out);
}

}  // namespace

void downsampleRowPair(const uint8_t* top, const uint8_t* bottom, uint32_t width, uint32_t channels,
                       bool srgb, uint8_t* out) {
  downsampleRowPairWith<true>(top, bottom, width, channels, srgb, out);
}

void downsampleRowPairScalar(const uint8_t* top, const uint8_t* bottom, uint32_t width,
                             uint32_t channels, bool srgb, uint8_t* out) {
  downsampleRowPairWith<false>(top, bottom, width, channels, srgb, out);
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
