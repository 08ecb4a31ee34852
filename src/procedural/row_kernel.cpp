#include "procedural/row_kernel.h"

#include <algorithm>
#include <cstring>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace tessera::detail {

namespace {

int64_t floorDiv(int64_t a, int64_t b) {
  int64_t q = a / b;
  return (a % b != 0 && ((a < 0) != (b < 0))) ? q - 1 : q;
}
int64_t ceilDiv(int64_t a, int64_t b) {
  int64_t q = a / b;
  return (a % b != 0 && ((a < 0) == (b < 0))) ? q + 1 : q;
}

// Narrows [lo, hi] (offsets k from x_c) to where base + step * k lies in [low, high].
void clampLinear(int64_t base, int64_t step, int64_t low, int64_t high, int64_t& lo, int64_t& hi) {
  if (step == 0) {
    if (base < low || base > high) hi = lo - 1;
    return;
  }
  if (step > 0) {
    lo = std::max(lo, ceilDiv(low - base, step));
    hi = std::min(hi, floorDiv(high - base, step));
  } else {
    lo = std::max(lo, ceilDiv(high - base, step));
    hi = std::min(hi, floorDiv(low - base, step));
  }
}

inline uint32_t load32(const uint8_t* p) {
  uint32_t v;
  std::memcpy(&v, p, 4);
  return v;
}

// A texel's four channels as four 16-bit lanes of a 64-bit word ("SIMD within a register"):
// the filter's and the blend's products of an 8-bit value and an 8-bit weight fit a lane, so
// one multiplication serves four channels, with exactly the arithmetic of the scalar formulas.
constexpr uint64_t kLaneMask = 0x00FF00FF00FF00FFull;
constexpr uint64_t kLaneHalf = 0x0080008000800080ull;

inline uint64_t spread(uint32_t texel) {
  uint64_t x = texel;
  x = (x | (x << 16)) & 0x0000FFFF0000FFFFull;
  return (x | (x << 8)) & kLaneMask;
}

inline uint32_t compact(uint64_t x) {
  x = (x | (x >> 8)) & 0x0000FFFF0000FFFFull;
  return uint32_t(x | (x >> 16));
}

// (a (256 - f) + b f + 128) >> 8 in every lane: lanes never exceed 65408, so nothing carries.
inline uint64_t lerpLanes(uint64_t a, uint64_t b, uint32_t f) {
  return ((a * (256 - f) + b * f + kLaneHalf) >> 8) & kLaneMask;
}

// div255 in every lane (lanes at most 255 * 255).
inline uint64_t div255Lanes(uint64_t x) {
  const uint64_t t = x + kLaneHalf;
  return ((t + ((t >> 8) & kLaneMask)) >> 8) & kLaneMask;
}

// The four taps of the bilinear filter, packed RGBA, for a first tap (x0, y0) that may lie
// outside the image: colour from the nearest edge texel, alpha 0 (the rule of sampleInstance).
void edgeTaps(const MipLevel& mip, int64_t x0, int64_t y0, uint32_t taps[4]) {
  const int64_t w = mip.width_px, h = mip.height_px;
  const bool in_x0 = x0 >= 0, in_x1 = x0 + 1 < w, in_y0 = y0 >= 0, in_y1 = y0 + 1 < h;
  const int64_t cx0 = in_x0 ? x0 : 0, cx1 = in_x1 ? x0 + 1 : w - 1;
  const int64_t cy0 = in_y0 ? y0 : 0, cy1 = in_y1 ? y0 + 1 : h - 1;
  const uint8_t* t = mip.texels.data();
  taps[0] = load32(t + (cy0 * w + cx0) * 4);
  taps[1] = load32(t + (cy0 * w + cx1) * 4);
  taps[2] = load32(t + (cy1 * w + cx0) * 4);
  taps[3] = load32(t + (cy1 * w + cx1) * 4);
  if (!(in_x0 && in_y0)) taps[0] &= 0x00FFFFFFu;
  if (!(in_x1 && in_y0)) taps[1] &= 0x00FFFFFFu;
  if (!(in_x0 && in_y1)) taps[2] &= 0x00FFFFFFu;
  if (!(in_x1 && in_y1)) taps[3] &= 0x00FFFFFFu;
}

template <BlendMode kMode>
inline uint32_t blendedChannel(uint32_t b, uint32_t s) {
  if constexpr (kMode == BlendMode::kNormal) return s;
  if constexpr (kMode == BlendMode::kMultiply) return div255(b * s);
  if constexpr (kMode == BlendMode::kAdd) return std::min(255u, b + s);
  return b < 128 ? div255(2 * b * s) : 255 - div255(2 * (255 - b) * (255 - s));
}

// B(b, s) for the three colour lanes (the alpha lane is ignored by the caller).
template <BlendMode kMode>
inline uint64_t blendedLanes(uint64_t backdrop, uint64_t source) {
  if constexpr (kMode == BlendMode::kNormal) return source;
  if constexpr (kMode == BlendMode::kAdd) {
    const uint64_t sum = backdrop + source;  // lanes <= 510
    const uint64_t over = (sum >> 8) & 0x0001000100010001ull;
    return (sum | (over * 0xFF)) & kLaneMask;
  }
  uint64_t out = 0;
  for (int c = 0; c < 3; ++c)
    out |= uint64_t(blendedChannel<kMode>(uint32_t(backdrop >> (16 * c)) & 0xFF,
                                          uint32_t(source >> (16 * c)) & 0xFF))
           << (16 * c);
  return out;
}

#if defined(__SSE2__)
// Two texels at once in SSE2's eight 16-bit lanes (lanes 0-3 the first texel's R, G, B, A,
// lanes 4-7 the second's): the same products, roundings and divisions as the scalar formulas,
// so the results are identical (the tests compare with the brute-force reference).
inline __m128i pairOf(uint32_t a, uint32_t b) {
  return _mm_unpacklo_epi8(_mm_unpacklo_epi32(_mm_cvtsi32_si128(int(a)), _mm_cvtsi32_si128(int(b))),
                           _mm_setzero_si128());
}
inline __m128i weightsOf(uint32_t a, uint32_t b) {
  return _mm_unpacklo_epi64(_mm_set1_epi16(short(a)), _mm_set1_epi16(short(b)));
}
inline __m128i lerp16(__m128i a, __m128i b, __m128i f) {
  const __m128i g = _mm_sub_epi16(_mm_set1_epi16(256), f);
  const __m128i sum = _mm_add_epi16(_mm_add_epi16(_mm_mullo_epi16(a, g), _mm_mullo_epi16(b, f)),
                                    _mm_set1_epi16(128));
  return _mm_srli_epi16(sum, 8);
}
inline __m128i div255x16(__m128i x) {
  const __m128i t = _mm_add_epi16(x, _mm_set1_epi16(128));
  return _mm_srli_epi16(_mm_add_epi16(t, _mm_srli_epi16(t, 8)), 8);
}
template <BlendMode kMode>
inline __m128i blended16(__m128i b, __m128i s) {
  if constexpr (kMode == BlendMode::kNormal) return s;
  if constexpr (kMode == BlendMode::kMultiply) return div255x16(_mm_mullo_epi16(b, s));
  if constexpr (kMode == BlendMode::kAdd)
    return _mm_min_epi16(_mm_add_epi16(b, s), _mm_set1_epi16(255));
  const __m128i full = _mm_set1_epi16(255);
  const __m128i low = _mm_cmplt_epi16(b, _mm_set1_epi16(128));
  const __m128i dark = div255x16(_mm_mullo_epi16(_mm_add_epi16(b, b), s));
  const __m128i inv_b = _mm_sub_epi16(full, b);
  const __m128i light = _mm_sub_epi16(
      full, div255x16(_mm_mullo_epi16(_mm_add_epi16(inv_b, inv_b), _mm_sub_epi16(full, s))));
  return _mm_or_si128(_mm_and_si128(low, dark), _mm_andnot_si128(low, light));
}
#endif

/// The bilinear taps of the sample at fixed point (u, v), packed RGBA.
inline void gatherTaps(const MipLevel& mip, int64_t u, int64_t v, uint32_t taps[4]) {
  const int64_t w = mip.width_px, h = mip.height_px;
  const int64_t x0 = u >> 16, y0 = v >> 16;
  TESSERA_DCHECK(x0 >= -1 && x0 < w && y0 >= -1 && y0 < h) << "outside the row span";
  if (x0 >= 0 && x0 + 1 < w && y0 >= 0 && y0 + 1 < h) {
    const uint8_t* p = mip.texels.data() + (y0 * w + x0) * 4;
    taps[0] = load32(p);
    taps[1] = load32(p + 4);
    taps[2] = load32(p + w * 4);
    taps[3] = load32(p + w * 4 + 4);
  } else {
    edgeTaps(mip, x0, y0, taps);
  }
}

/// Mask and blend of one filtered, tinted source texel (colour lanes 0, 16, 32 of `colour`).
template <BlendMode kMode>
inline void finishTexel(const InstanceSetup& setup, uint64_t colour, uint32_t alpha,
                        const uint8_t* mask_value, uint8_t* d) {
  if (mask_value) alpha = div255(alpha * setup.brush->mask_lut[*mask_value]);
  if (alpha == 0) return;
  const uint32_t backdrop = load32(d);
  const uint32_t backdrop_alpha = backdrop >> 24;
  if (backdrop_alpha == 255) {
    const uint64_t b = spread(backdrop);
    const uint64_t mixed = div255Lanes(blendedLanes<kMode>(b, colour) * alpha + b * (255 - alpha));
    const uint32_t out = (compact(mixed) & 0x00FFFFFFu) | 0xFF000000u;
    std::memcpy(d, &out, 4);
  } else if (backdrop_alpha == 0) {
    // Nothing below: blendTexel gives the source as it is (s' = s, ao = as).
    const uint32_t out = (compact(colour) & 0x00FFFFFFu) | (alpha << 24);
    std::memcpy(d, &out, 4);
  } else {
    const uint8_t s[4] = {uint8_t(colour), uint8_t(colour >> 16), uint8_t(colour >> 32),
                          uint8_t(alpha)};
    blendTexel(kMode, s, alpha, d);
  }
}

/// One texel by the scalar formulas: filter, tint, then finishTexel.
template <BlendMode kMode>
inline void drawTexel(const InstanceSetup& setup, bool plain, int64_t u, int64_t v,
                      const uint8_t* mask_value, uint8_t* d) {
  uint32_t taps[4];
  gatherTaps(*setup.mip, u, v, taps);
  const uint32_t fx = uint32_t(u >> 8) & 0xFF, fy = uint32_t(v >> 8) & 0xFF;
  uint64_t colour = lerpLanes(lerpLanes(spread(taps[0]), spread(taps[1]), fx),
                              lerpLanes(spread(taps[2]), spread(taps[3]), fx), fy);
  uint32_t alpha = uint32_t(colour >> 48);
  if (alpha == 0) return;
  if (!plain) {
    uint64_t tinted = 0;
    for (int c = 0; c < 3; ++c)
      tinted |= uint64_t(div255(uint32_t(colour >> (16 * c) & 0xFF) * setup.tint[c])) << (16 * c);
    colour = tinted;
    alpha = div255(div255(alpha * setup.tint[3]) * setup.opacity);
  }
  finishTexel<kMode>(setup, colour, alpha, mask_value, d);
}

#if defined(__SSE2__)
/// The colour lanes kFirst..kFirst + 2 of a pair register as finishTexel takes them (16 bits
/// apart). A template because _mm_extract_epi16 needs a constant lane: clang rejects a lane
/// that is only constant after inlining, which GCC accepts.
template <int kFirst>
inline uint64_t colourLanes(__m128i colour) {
  return uint64_t(_mm_extract_epi16(colour, kFirst)) |
         uint64_t(_mm_extract_epi16(colour, kFirst + 1)) << 16 |
         uint64_t(_mm_extract_epi16(colour, kFirst + 2)) << 32;
}

/// Two texels (k and k + 1) in one register; falls back to finishTexel per texel unless both
/// draw over an opaque backdrop.
template <BlendMode kMode>
inline void drawPair(const InstanceSetup& setup, bool plain, int64_t u, int64_t v,
                     const uint8_t* mask_values, uint8_t* d) {
  uint32_t a[4], b[4];
  gatherTaps(*setup.mip, u, v, a);
  gatherTaps(*setup.mip, u + setup.du_dx, v + setup.dv_dx, b);
  const __m128i fx = weightsOf(uint32_t(u >> 8) & 0xFF, uint32_t((u + setup.du_dx) >> 8) & 0xFF);
  const __m128i fy = weightsOf(uint32_t(v >> 8) & 0xFF, uint32_t((v + setup.dv_dx) >> 8) & 0xFF);
  __m128i colour = lerp16(lerp16(pairOf(a[0], b[0]), pairOf(a[1], b[1]), fx),
                          lerp16(pairOf(a[2], b[2]), pairOf(a[3], b[3]), fx), fy);
  if (!plain) {
    // Colour lanes: div255(c t); alpha: div255(div255(a t) opacity); div255(x 255) = x.
    const __m128i tint = _mm_setr_epi16(
        short(setup.tint[0]), short(setup.tint[1]), short(setup.tint[2]), short(setup.tint[3]),
        short(setup.tint[0]), short(setup.tint[1]), short(setup.tint[2]), short(setup.tint[3]));
    const __m128i opacity =
        _mm_setr_epi16(255, 255, 255, short(setup.opacity), 255, 255, 255, short(setup.opacity));
    colour = div255x16(_mm_mullo_epi16(div255x16(_mm_mullo_epi16(colour, tint)), opacity));
  }
  uint32_t alpha_a = uint32_t(_mm_extract_epi16(colour, 3));
  uint32_t alpha_b = uint32_t(_mm_extract_epi16(colour, 7));
  if (mask_values) {
    alpha_a = div255(alpha_a * setup.brush->mask_lut[mask_values[0]]);
    alpha_b = div255(alpha_b * setup.brush->mask_lut[mask_values[1]]);
  }
  if (alpha_a && alpha_b && d[3] == 255 && d[7] == 255) {
    const __m128i backdrop = _mm_unpacklo_epi8(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(d)),
                                               _mm_setzero_si128());
    const __m128i sa = weightsOf(alpha_a, alpha_b);
    const __m128i out =
        div255x16(_mm_add_epi16(_mm_mullo_epi16(blended16<kMode>(backdrop, colour), sa),
                                _mm_mullo_epi16(backdrop, _mm_sub_epi16(_mm_set1_epi16(255), sa))));
    _mm_storel_epi64(reinterpret_cast<__m128i*>(d), _mm_packus_epi16(out, out));
    d[3] = d[7] = 255;
    return;
  }
  if (alpha_a && alpha_b && d[3] == 0 && d[7] == 0) {
    // Nothing below either: the source as it is (see finishTexel).
    const __m128i out =
        _mm_insert_epi16(_mm_insert_epi16(colour, int(alpha_a), 3), int(alpha_b), 7);
    _mm_storel_epi64(reinterpret_cast<__m128i*>(d), _mm_packus_epi16(out, out));
    return;
  }
  // Masks are applied already: finish without them.
  if (alpha_a) finishTexel<kMode>(setup, colourLanes<0>(colour), alpha_a, nullptr, d);
  if (alpha_b) finishTexel<kMode>(setup, colourLanes<4>(colour), alpha_b, nullptr, d + 4);
}
#endif

/// The row loop for one blend mode: filter, tint, mask and blend each texel in place.
template <BlendMode kMode>
void drawRow(const InstanceSetup& setup, int64_t dy, int64_t first, int64_t last,
             const uint8_t* mask_values, uint8_t* row) {
  const bool plain =
      setup.tint == std::array<uint32_t, 4>{255, 255, 255, 255} && setup.opacity == 255;
  // The span keeps every texel's first tap in [-1, w) x [-1, h) and within reach, so each is
  // drawn exactly as sampleInstance would; coordinates advance by addition (exact integers).
  const int64_t dx0 = first - setup.x_c;
  int64_t u = setup.u_c + setup.du_dx * dx0 + setup.du_dy * dy;
  int64_t v = setup.v_c + setup.dv_dx * dx0 + setup.dv_dy * dy;
  const int64_t count = last - first + 1;
  int64_t k = 0;
#if defined(__SSE2__)
  for (; k + 1 < count; k += 2, u += 2 * setup.du_dx, v += 2 * setup.dv_dx)
    drawPair<kMode>(setup, plain, u, v, mask_values ? mask_values + k : nullptr, row + k * 4);
#endif
  for (; k < count; ++k, u += setup.du_dx, v += setup.dv_dx)
    drawTexel<kMode>(setup, plain, u, v, mask_values ? mask_values + k : nullptr, row + k * 4);
}

}  // namespace

RowSpan instanceRowSpan(const InstanceSetup& setup, int64_t y) {
  RowSpan span;
  const int64_t dy = y - setup.y_c;
  if (dy > setup.reach || dy < -setup.reach) return span;
  int64_t lo = -setup.reach, hi = setup.reach;
  const int64_t w = setup.mip->width_px, h = setup.mip->height_px;
  // x0 = u >> 16 in [-1, w) and y0 in [-1, h): u in [-65536, w * 65536 - 1].
  clampLinear(setup.u_c + setup.du_dy * dy, setup.du_dx, -65536, w * 65536 - 1, lo, hi);
  clampLinear(setup.v_c + setup.dv_dy * dy, setup.dv_dx, -65536, h * 65536 - 1, lo, hi);
  span.first = setup.x_c + lo;
  span.last = setup.x_c + hi;
  return span;
}

void drawInstanceRow(const InstanceSetup& setup, int64_t y, int64_t first, int64_t last,
                     const uint8_t* mask_values, uint8_t* row) {
  const int64_t dy = y - setup.y_c;
  switch (setup.brush->blend) {
    case BlendMode::kNormal:
      drawRow<BlendMode::kNormal>(setup, dy, first, last, mask_values, row);
      break;
    case BlendMode::kMultiply:
      drawRow<BlendMode::kMultiply>(setup, dy, first, last, mask_values, row);
      break;
    case BlendMode::kAdd: drawRow<BlendMode::kAdd>(setup, dy, first, last, mask_values, row); break;
    case BlendMode::kOverlay:
      drawRow<BlendMode::kOverlay>(setup, dy, first, last, mask_values, row);
      break;
  }
}

void instanceRowAlpha(const InstanceSetup& setup, int64_t y, int64_t first, int64_t last,
                      uint8_t* alpha) {
  const MipLevel& mip = *setup.mip;
  const int64_t w = mip.width_px, h = mip.height_px;
  const uint8_t* texels = mip.texels.data();
  const int64_t dy = y - setup.y_c, dx0 = first - setup.x_c;
  int64_t u = setup.u_c + setup.du_dx * dx0 + setup.du_dy * dy;
  int64_t v = setup.v_c + setup.dv_dx * dx0 + setup.dv_dy * dy;
  const bool plain = setup.tint[3] == 255 && setup.opacity == 255;
  auto at = [&](int64_t x, int64_t yy) -> uint32_t {
    return x >= 0 && x < w && yy >= 0 && yy < h ? texels[(yy * w + x) * 4 + 3] : 0;
  };
  for (int64_t k = 0; k <= last - first; ++k, u += setup.du_dx, v += setup.dv_dx) {
    const int64_t x0 = u >> 16, y0 = v >> 16;
    const uint32_t fx = uint32_t(u >> 8) & 0xFF, fy = uint32_t(v >> 8) & 0xFF;
    uint32_t a;
    if (x0 >= 0 && x0 + 1 < w && y0 >= 0 && y0 + 1 < h) {
      const uint8_t* p = texels + (y0 * w + x0) * 4 + 3;
      a = bilinear(p[0], p[4], p[w * 4], p[w * 4 + 4], fx, fy);
    } else {
      a = bilinear(at(x0, y0), at(x0 + 1, y0), at(x0, y0 + 1), at(x0 + 1, y0 + 1), fx, fy);
    }
    if (a != 0 && !plain) a = div255(div255(a * setup.tint[3]) * setup.opacity);
    alpha[k] = uint8_t(a);
  }
}

}  // namespace tessera::detail
