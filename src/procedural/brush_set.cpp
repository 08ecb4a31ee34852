// BrushSet::prepare: brush images' mip pyramids and the underlying layer's height and slope
// pyramids (docs/procedural.md, "Filtering" and "Masks").
#include <tessera/procedural.h>

#include <algorithm>
#include <cmath>
#include <deque>

#include <fmt/format.h>

#include "procedural/kernel.h"

namespace tessera {

using namespace detail;

namespace {

// Alpha-weighted 2x2 mean (the builder's rule, docs/format.md "Downsampling"): colour is
// sum(c a) / sum(a) rounded, alpha the rounded mean; an odd last row or column is averaged
// with itself.
MipLevel halveRgba(const MipLevel& in) {
  MipLevel out;
  out.width_px = (in.width_px + 1) / 2;
  out.height_px = (in.height_px + 1) / 2;
  out.texels.resize(size_t(out.width_px) * out.height_px * 4);
  for (uint32_t y = 0; y < out.height_px; ++y) {
    uint32_t y0 = 2 * y, y1 = std::min(2 * y + 1, in.height_px - 1);
    for (uint32_t x = 0; x < out.width_px; ++x) {
      uint32_t x0 = 2 * x, x1 = std::min(2 * x + 1, in.width_px - 1);
      const uint8_t* taps[4] = {&in.texels[(size_t(y0) * in.width_px + x0) * 4],
                                &in.texels[(size_t(y0) * in.width_px + x1) * 4],
                                &in.texels[(size_t(y1) * in.width_px + x0) * 4],
                                &in.texels[(size_t(y1) * in.width_px + x1) * 4]};
      uint32_t alpha_sum = 0;
      for (const uint8_t* t : taps) alpha_sum += t[3];
      uint8_t* o = &out.texels[(size_t(y) * out.width_px + x) * 4];
      for (int c = 0; c < 3; ++c) {
        uint32_t sum = 0;
        for (const uint8_t* t : taps) sum += uint32_t(t[c]) * t[3];
        o[c] = alpha_sum ? uint8_t((sum + alpha_sum / 2) / alpha_sum) : 0;
      }
      o[3] = uint8_t((alpha_sum + 2) >> 2);
    }
  }
  return out;
}

MipLevel halveGray(const MipLevel& in) {
  MipLevel out;
  out.width_px = (in.width_px + 1) / 2;
  out.height_px = (in.height_px + 1) / 2;
  out.texels.resize(size_t(out.width_px) * out.height_px);
  for (uint32_t y = 0; y < out.height_px; ++y) {
    uint32_t y0 = 2 * y, y1 = std::min(2 * y + 1, in.height_px - 1);
    for (uint32_t x = 0; x < out.width_px; ++x) {
      uint32_t x0 = 2 * x, x1 = std::min(2 * x + 1, in.width_px - 1);
      uint32_t sum =
          in.texels[size_t(y0) * in.width_px + x0] + in.texels[size_t(y0) * in.width_px + x1] +
          in.texels[size_t(y1) * in.width_px + x0] + in.texels[size_t(y1) * in.width_px + x1];
      out.texels[size_t(y) * out.width_px + x] = uint8_t((sum + 2) >> 2);
    }
  }
  return out;
}

// Fully transparent texels take the colour of the nearest texel with alpha (breadth first from
// every such texel at once, 4-neighbours, scan order breaking ties), so that bilinear taps at a
// brush's edge blend towards its own colours rather than towards whatever a painter left under
// alpha 0. Alpha is untouched.
void bleedColour(MipLevel& mip) {
  const uint32_t w = mip.width_px, h = mip.height_px;
  std::vector<uint8_t> filled(size_t(w) * h, 0);
  std::deque<uint32_t> queue;
  for (uint32_t i = 0; i < w * h; ++i) {
    if (mip.texels[size_t(i) * 4 + 3] != 0) {
      filled[i] = 1;
      queue.push_back(i);
    }
  }
  while (!queue.empty()) {
    uint32_t i = queue.front();
    queue.pop_front();
    uint32_t x = i % w, y = i / w;
    const uint32_t neighbours[4] = {y > 0 ? i - w : i, x > 0 ? i - 1 : i, x + 1 < w ? i + 1 : i,
                                    y + 1 < h ? i + w : i};
    for (uint32_t n : neighbours) {
      if (filled[n]) continue;
      filled[n] = 1;
      for (int c = 0; c < 3; ++c) mip.texels[size_t(n) * 4 + c] = mip.texels[size_t(i) * 4 + c];
      queue.push_back(n);
    }
  }
}

ImagePyramid rgbaPyramid(const Image& image) {
  ImagePyramid pyramid;
  MipLevel base{image.width_px, image.height_px, image.texels};
  pyramid.mips.push_back(std::move(base));
  while (pyramid.mips.back().width_px > 1 || pyramid.mips.back().height_px > 1)
    pyramid.mips.push_back(halveRgba(pyramid.mips.back()));
  for (MipLevel& mip : pyramid.mips) bleedColour(mip);
  return pyramid;
}

LayerPyramid grayPyramid(MipLevel base) {
  LayerPyramid pyramid;
  pyramid.mips.push_back(std::move(base));
  while (pyramid.mips.back().width_px > 1 || pyramid.mips.back().height_px > 1)
    pyramid.mips.push_back(halveGray(pyramid.mips.back()));
  return pyramid;
}

// Slope from the height image by central differences (one-sided at the edges):
// min(255, round(2 * sqrt(gx^2 + gy^2))) with gx, gy the height differences across two texels.
// sqrt is correctly rounded in IEEE arithmetic, so the layer is the same on every machine.
MipLevel slopeOf(const Image& height) {
  const uint32_t w = height.width_px, h = height.height_px;
  MipLevel slope{w, h, std::vector<uint8_t>(size_t(w) * h)};
  auto at = [&](uint32_t x, uint32_t y) { return int32_t(height.texels[size_t(y) * w + x]); };
  for (uint32_t y = 0; y < h; ++y) {
    for (uint32_t x = 0; x < w; ++x) {
      int32_t gx = at(std::min(x + 1, w - 1), y) - at(x > 0 ? x - 1 : 0, y);
      int32_t gy = at(x, std::min(y + 1, h - 1)) - at(x, y > 0 ? y - 1 : 0);
      double magnitude = 2 * std::sqrt(double(gx * gx + gy * gy));
      slope.texels[size_t(y) * w + x] = uint8_t(std::min(255.0, std::nearbyint(magnitude)));
    }
  }
  return slope;
}

// The mask ramp as a table: 0 at mask_low, 255 at mask_high, linear and rounded between;
// inverted when low > high; a step at low when they are equal.
std::array<uint8_t, 256> maskTable(const Brush& brush) {
  std::array<uint8_t, 256> table{};
  int low = brush.mask_low, high = brush.mask_high;
  for (int v = 0; v < 256; ++v) {
    int value;
    if (low == high) {
      value = v >= low ? 255 : 0;
    } else if (low < high) {
      int t = std::clamp(v - low, 0, high - low);
      value = (t * 255 + (high - low) / 2) / (high - low);
    } else {
      int t = std::clamp(low - v, 0, low - high);
      value = (t * 255 + (low - high) / 2) / (low - high);
    }
    table[v] = uint8_t(value);
  }
  return table;
}

}  // namespace

BrushSet::BrushSet(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
BrushSet::~BrushSet() = default;

const std::vector<Brush>& BrushSet::brushes() const {
  return impl_->brushes;
}
uint32_t BrushSet::textureWidthPx() const {
  return impl_->texture_width_px;
}
uint32_t BrushSet::textureHeightPx() const {
  return impl_->texture_height_px;
}
bool BrushSet::hasLayer() const {
  return !impl_->height.empty();
}

Result<std::shared_ptr<const BrushSet>> BrushSet::prepare(std::vector<Brush> brushes,
                                                          UnderlyingLayer layer,
                                                          uint32_t texture_width_px,
                                                          uint32_t texture_height_px) {
  if (texture_width_px == 0 || texture_height_px == 0 || texture_width_px > kMaxImageSidePx ||
      texture_height_px > kMaxImageSidePx)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("texture size {}x{} out of 1..{}", texture_width_px, texture_height_px,
                            kMaxImageSidePx));
  auto impl = std::make_unique<Impl>();
  impl->texture_width_px = texture_width_px;
  impl->texture_height_px = texture_height_px;
  bool has_layer = layer.height.width_px > 0 && layer.height.height_px > 0;
  if (has_layer) {
    if (layer.height.channels != 1 ||
        layer.height.texels.size() != size_t(layer.height.width_px) * layer.height.height_px)
      return fail(ErrorCode::kInvalidArgument, "height layer: must be one 8-bit gray channel");
    impl->slope = grayPyramid(slopeOf(layer.height));
    impl->height = grayPyramid(
        MipLevel{layer.height.width_px, layer.height.height_px, std::move(layer.height.texels)});
  }
  impl->prepared.reserve(brushes.size());
  for (size_t b = 0; b < brushes.size(); ++b) {
    const Brush& brush = brushes[b];
    std::string what = fmt::format("brush {} ({})", b, brush.name);
    TESSERA_TRY(validateBrush(brush, what));
    if (brush.mask != MaskSource::kNone && !has_layer)
      return fail(ErrorCode::kInvalidArgument, what + ": masked by " + maskSourceName(brush.mask) +
                                                   " but no underlying layer was given");
    PreparedBrush prepared;
    prepared.blend = brush.blend;
    prepared.mask = brush.mask;
    prepared.mask_lut = maskTable(brush);
    for (const Image& image : brush.images) prepared.images.push_back(rgbaPyramid(image));
    impl->prepared.push_back(std::move(prepared));
  }
  impl->brushes = std::move(brushes);
  return std::shared_ptr<const BrushSet>(new BrushSet(std::move(impl)));
}

}  // namespace tessera
