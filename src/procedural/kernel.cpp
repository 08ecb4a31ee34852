// The compositor's per-instance setup and per-texel arithmetic (docs/procedural.md,
// "Filtering", "Blend modes", "Determinism").
#include "procedural/kernel.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include <fmt/format.h>

#include "det_math.h"

namespace tessera::detail {

namespace {

constexpr double kSqrt2 = 1.4142135623730951;
/// Bound on a fixed-point step, so that step * reach stays far inside 64 bits.
constexpr double kMaxStep = 70368744177664.0;  // 2^46

int64_t toFixed(double value) {
  return std::llround(std::clamp(value, -kMaxStep, kMaxStep) * 65536.0);
}

// The mip whose texel is nearest in size to the target texel: the first m with
// texels_per_target <= sqrt(2) * 2^m (GL's LINEAR_MIPMAP_NEAREST rule).
uint32_t chooseMip(double texels_per_target, size_t mip_count) {
  uint32_t m = 0;
  while (m + 1 < mip_count && texels_per_target > kSqrt2 * std::ldexp(1.0, int(m))) ++m;
  return m;
}

}  // namespace

Result<InstanceSetup> setupInstance(const BrushSet::Impl& set, const BrushInstance& instance,
                                    uint32_t level) {
  if (instance.brush >= set.prepared.size())
    return fail(ErrorCode::kCorrupt, fmt::format("instance {} names brush {}, the brush set has {}",
                                                 instance.id, instance.brush, set.prepared.size()));
  InstanceSetup setup;
  setup.brush = &set.prepared[instance.brush];
  if (setup.brush->mask != MaskSource::kNone &&
      (setup.brush->mask == MaskSource::kHeight ? set.height.empty() : set.slope.empty()))
    return fail(ErrorCode::kCorrupt,
                fmt::format("instance {}: brush {} is masked by a layer the set lacks", instance.id,
                            instance.brush));
  const ImagePyramid& image = setup.brush->images[instance.variant % setup.brush->images.size()];
  const MipLevel& base = image.mips[0];
  const double w = base.width_px, h = base.height_px;
  const double extent = double(instance.radius_px) * double(instance.scale);
  const double per_px = std::max(w, h) / (2 * extent);  // brush texels per level-0 texel
  const double level_px = std::ldexp(1.0, int(level));  // level-0 texels per level texel
  setup.mip_index = chooseMip(per_px * level_px, image.mips.size());
  setup.mip = &image.mips[setup.mip_index];
  const double sx = setup.mip->width_px / w, sy = setup.mip->height_px / h;
  double sine, cosine;
  detSinCos(instance.rotation_rad, &sine, &cosine);
  setup.x_c = int64_t(std::floor(instance.x_px / level_px));
  setup.y_c = int64_t(std::floor(instance.y_px / level_px));
  setup.reach = int64_t(std::floor(extent * kSqrt2 / level_px)) + 2;
  // Brush coordinates of the texel centre (x_c + 1/2, y_c + 1/2): the offset from the
  // instance's centre rotated by -rotation, in brush texels, from the image's centre.
  const double dx = (double(setup.x_c) + 0.5) * level_px - instance.x_px;
  const double dy = (double(setup.y_c) + 0.5) * level_px - instance.y_px;
  const double local_x = dx * cosine + dy * sine;
  const double local_y = dy * cosine - dx * sine;
  setup.u_c = toFixed((w / 2 + local_x * per_px) * sx - 0.5);
  setup.v_c = toFixed((h / 2 + local_y * per_px) * sy - 0.5);
  setup.du_dx = toFixed(level_px * cosine * per_px * sx);
  setup.du_dy = toFixed(level_px * sine * per_px * sx);
  setup.dv_dx = toFixed(-level_px * sine * per_px * sy);
  setup.dv_dy = toFixed(level_px * cosine * per_px * sy);
  for (int c = 0; c < 4; ++c) setup.tint[c] = (instance.tint_rgba >> (8 * c)) & 0xFF;
  setup.opacity = instance.opacity;
  return setup;
}

uint32_t sampleInstance(const InstanceSetup& setup, int64_t x, int64_t y, uint8_t rgba[4]) {
  const int64_t dx = x - setup.x_c, dy = y - setup.y_c;
  if (dx > setup.reach || dx < -setup.reach || dy > setup.reach || dy < -setup.reach) return 0;
  const int64_t u = setup.u_c + setup.du_dx * dx + setup.du_dy * dy;
  const int64_t v = setup.v_c + setup.dv_dx * dx + setup.dv_dy * dy;
  const int64_t x0 = u >> 16, y0 = v >> 16;  // floor: arithmetic shifts (C++20)
  const int64_t w = setup.mip->width_px, h = setup.mip->height_px;
  if (x0 < -1 || x0 >= w || y0 < -1 || y0 >= h) return 0;
  const uint32_t fx = uint32_t(u >> 8) & 0xFF, fy = uint32_t(v >> 8) & 0xFF;
  // Taps outside the image have alpha 0 and the colour of the nearest edge texel.
  const bool in_x0 = x0 >= 0, in_x1 = x0 + 1 < w, in_y0 = y0 >= 0, in_y1 = y0 + 1 < h;
  const int64_t cx0 = in_x0 ? x0 : 0, cx1 = in_x1 ? x0 + 1 : w - 1;
  const int64_t cy0 = in_y0 ? y0 : 0, cy1 = in_y1 ? y0 + 1 : h - 1;
  const uint8_t* texels = setup.mip->texels.data();
  const uint8_t* t00 = texels + (cy0 * w + cx0) * 4;
  const uint8_t* t10 = texels + (cy0 * w + cx1) * 4;
  const uint8_t* t01 = texels + (cy1 * w + cx0) * 4;
  const uint8_t* t11 = texels + (cy1 * w + cx1) * 4;
  const uint32_t a00 = in_x0 && in_y0 ? t00[3] : 0, a10 = in_x1 && in_y0 ? t10[3] : 0;
  const uint32_t a01 = in_x0 && in_y1 ? t01[3] : 0, a11 = in_x1 && in_y1 ? t11[3] : 0;
  uint32_t alpha = bilinear(a00, a10, a01, a11, fx, fy);
  if (alpha == 0) return 0;
  for (int c = 0; c < 3; ++c)
    rgba[c] = uint8_t(div255(bilinear(t00[c], t10[c], t01[c], t11[c], fx, fy) * setup.tint[c]));
  alpha = div255(div255(alpha * setup.tint[3]) * setup.opacity);
  rgba[3] = uint8_t(alpha);
  return alpha;
}

LayerTaps layerTaps(const LayerPyramid& layer, uint32_t texture_width_px,
                    uint32_t texture_height_px, uint32_t level, int64_t x, int64_t y) {
  const MipLevel& base = layer.mips[0];
  const double level_px = std::ldexp(1.0, int(level));
  const double per_target = std::max(double(base.width_px) / texture_width_px,
                                     double(base.height_px) / texture_height_px) *
                            level_px;
  LayerTaps taps;
  taps.mip = chooseMip(per_target, layer.mips.size());
  const MipLevel& mip = layer.mips[taps.mip];
  const int64_t u = toFixed((double(x) + 0.5) * level_px * mip.width_px / texture_width_px - 0.5);
  const int64_t v = toFixed((double(y) + 0.5) * level_px * mip.height_px / texture_height_px - 0.5);
  const int64_t w = mip.width_px, h = mip.height_px;
  taps.x0 = std::clamp<int64_t>(u >> 16, 0, w - 1);
  taps.x1 = std::clamp<int64_t>((u >> 16) + 1, 0, w - 1);
  taps.y0 = std::clamp<int64_t>(v >> 16, 0, h - 1);
  taps.y1 = std::clamp<int64_t>((v >> 16) + 1, 0, h - 1);
  taps.fx = uint32_t(u >> 8) & 0xFF;
  taps.fy = uint32_t(v >> 8) & 0xFF;
  return taps;
}

uint8_t sampleLayer(const LayerPyramid& layer, uint32_t texture_width_px,
                    uint32_t texture_height_px, uint32_t level, int64_t x, int64_t y) {
  const LayerTaps taps = layerTaps(layer, texture_width_px, texture_height_px, level, x, y);
  const MipLevel& mip = layer.mips[taps.mip];
  const int64_t w = mip.width_px;
  const uint8_t* t = mip.texels.data();
  const uint32_t gx = 256 - taps.fx, gy = 256 - taps.fy;
  return uint8_t(((t[taps.y0 * w + taps.x0] * gx + t[taps.y0 * w + taps.x1] * taps.fx) * gy +
                  (t[taps.y1 * w + taps.x0] * gx + t[taps.y1 * w + taps.x1] * taps.fx) * taps.fy +
                  32768) >>
                 16);
}

namespace {

uint32_t blendChannel(BlendMode mode, uint32_t b, uint32_t s) {
  switch (mode) {
    case BlendMode::kNormal: return s;
    case BlendMode::kMultiply: return div255(b * s);
    case BlendMode::kAdd: return std::min(255u, b + s);
    case BlendMode::kOverlay:
      return b < 128 ? div255(2 * b * s) : 255 - div255(2 * (255 - b) * (255 - s));
  }
  return s;
}

}  // namespace

// The W3C compositing model in straight alpha: the blended colour
// s' = ((1 - ab) s + ab B(b, s)), then source-over: ao = as + ab (1 - as),
// co = (as s' + ab (1 - as) b) / ao; every product rounded to 8 bits as it is formed.
void blendTexel(BlendMode mode, const uint8_t s[4], uint32_t sa, uint8_t dst[4]) {
  const uint32_t ab = dst[3];
  if (ab == 255) {
    // An opaque backdrop (the common case under a base layer): s' = B(b, s), ao = 1, and the
    // division by ao is the rounded division by 255.
    for (int c = 0; c < 3; ++c)
      dst[c] = uint8_t(div255(sa * blendChannel(mode, dst[c], s[c]) + (255 - sa) * dst[c]));
    return;
  }
  if (ab == 0) {
    // Nothing below: s' = s, ao = as and co = (as s + as / 2) / as = s exactly.
    std::memcpy(dst, s, 3);
    dst[3] = uint8_t(sa);
    return;
  }
  const uint32_t backdrop_weight = div255(ab * (255 - sa));
  const uint32_t ao = sa + backdrop_weight;
  for (int c = 0; c < 3; ++c) {
    const uint32_t b = dst[c];
    const uint32_t mixed = div255((255 - ab) * s[c] + ab * blendChannel(mode, b, s[c]));
    dst[c] = uint8_t((sa * mixed + backdrop_weight * b + ao / 2) / ao);
  }
  dst[3] = uint8_t(ao);
}

}  // namespace tessera::detail
