#pragma once
// Brushes and instance sets for the procedural tests: small RGBA images with soft alpha, every
// blend mode, masked brushes over a height layer, and random overlapping instances from a
// seed (deterministic).

#include <cstdint>
#include <random>
#include <vector>

#include <tessera/procedural.h>

namespace tessera::testing {

/// A w x h RGBA image of one colour.
inline Image solidImage(uint32_t w, uint32_t h, uint8_t r, uint8_t g, uint8_t b, uint8_t a) {
  Image image(w, h, 4);
  for (size_t i = 0; i < size_t(w) * h; ++i) {
    image.texels[i * 4 + 0] = r;
    image.texels[i * 4 + 1] = g;
    image.texels[i * 4 + 2] = b;
    image.texels[i * 4 + 3] = a;
  }
  return image;
}

/// A round stamp: colour varying across the image, alpha falling off towards a disc's edge,
/// zero in the corners (painted with junk colour under alpha 0, which bleeding must hide).
inline Image stampImage(uint32_t side, uint32_t seed) {
  Image image(side, side, 4);
  std::mt19937 rng(seed);
  const double c = side / 2.0;
  for (uint32_t y = 0; y < side; ++y) {
    for (uint32_t x = 0; x < side; ++x) {
      uint8_t* t = &image.texels[(size_t(y) * side + x) * 4];
      double d = std::hypot(x + 0.5 - c, y + 0.5 - c) / c;
      t[0] = uint8_t((x * 255) / side);
      t[1] = uint8_t((y * 255) / side);
      t[2] = uint8_t(rng() & 0xFF);
      t[3] = d >= 1 ? 0 : uint8_t(std::min(255.0, (1 - d) * 400));
      if (t[3] == 0) t[0] = t[1] = t[2] = 0;
    }
  }
  return image;
}

/// A gray height layer: a ramp with a ridge, so slopes vary.
inline Image heightLayer(uint32_t w, uint32_t h) {
  Image image(w, h, 1);
  for (uint32_t y = 0; y < h; ++y)
    for (uint32_t x = 0; x < w; ++x)
      image.texels[size_t(y) * w + x] =
          uint8_t(std::min<uint32_t>(255, (x * 200) / w + ((x + y) % 17 < 8 ? 40 : 0)));
  return image;
}

/// Six brushes: a square opaque base (normal), a soft stamp for each blend mode, and a
/// slope-masked and a height-masked one.
inline std::vector<Brush> testBrushes() {
  std::vector<Brush> brushes;
  auto add = [&](const char* name, BlendMode mode, MaskSource mask, std::vector<Image> images) {
    Brush brush;
    brush.name = name;
    brush.blend = mode;
    brush.mask = mask;
    brush.mask_low = mask == MaskSource::kSlope ? 20 : 200;
    brush.mask_high = mask == MaskSource::kSlope ? 90 : 60;
    brush.images = std::move(images);
    brushes.push_back(std::move(brush));
  };
  add("base", BlendMode::kNormal, MaskSource::kNone, {solidImage(16, 16, 90, 120, 60, 255)});
  add("stamp", BlendMode::kNormal, MaskSource::kNone, {stampImage(32, 1), stampImage(21, 2)});
  add("shade", BlendMode::kMultiply, MaskSource::kNone, {stampImage(16, 3)});
  add("glow", BlendMode::kAdd, MaskSource::kNone, {stampImage(24, 4)});
  add("detail", BlendMode::kOverlay, MaskSource::kNone, {stampImage(8, 5)});
  add("rock", BlendMode::kNormal, MaskSource::kSlope, {stampImage(64, 6)});
  add("snow", BlendMode::kNormal, MaskSource::kHeight, {solidImage(8, 8, 250, 250, 250, 255)});
  return brushes;
}

/// `count` instances over a w x h texture: a few large ones, many small ones, heavy overlap,
/// every brush, random rotation, scale, opacity and tint; layers small integers (ties exercise
/// the id order).
inline std::vector<BrushInstance> randomInstances(uint32_t count, uint32_t w, uint32_t h,
                                                  uint32_t brush_count, uint32_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0, 1);
  std::vector<BrushInstance> instances;
  for (uint32_t i = 0; i < count; ++i) {
    BrushInstance instance;
    instance.id = i + 1;
    instance.brush = uint32_t(rng() % brush_count);
    instance.x_px = unit(rng) * w;
    instance.y_px = unit(rng) * h;
    double size = unit(rng);
    instance.radius_px = float(i % 10 == 0 ? 20 + size * w / 2 : 0.3 + size * size * 40);
    instance.rotation_rad = float(unit(rng) * 6.3 - 3.15);
    instance.scale = float(0.5 + unit(rng));
    instance.opacity = uint8_t(rng() % 3 == 0 ? 255 : rng() & 0xFF);
    instance.tint_rgba = rng() % 2 ? 0xFFFFFFFFu : uint32_t(rng());
    instance.variant = uint8_t(rng() & 3);
    instance.layer = int32_t(rng() % 4);
    instances.push_back(instance);
  }
  return instances;
}

}  // namespace tessera::testing
