// Deterministic instance sets with a realistic mix (docs/procedural.md, "Generated instance
// sets"): a few large base-layer instances that tile the texture with overlap, medium patches,
// and many small detail stamps clustered around random centres so that they overlap heavily.
#include <tessera/brushes.h>

#include <algorithm>
#include <cmath>
#include <random>

namespace tessera {

std::vector<BrushInstance> generateInstances(uint64_t count, const TextureExtent& extent,
                                             uint32_t brush_count, uint64_t seed) {
  std::vector<BrushInstance> instances;
  if (count == 0 || brush_count == 0 || extent.width_px == 0 || extent.height_px == 0)
    return instances;
  instances.reserve(count);
  std::mt19937_64 rng(seed);
  auto unit = [&] { return double(rng() >> 11) * 0x1.0p-53; };
  const double w = extent.width_px, h = extent.height_px;
  // Base layer: a grid of instances twice the cell's size (so neighbours overlap), brush 0.
  const uint64_t base_side = std::clamp<uint64_t>(uint64_t(std::sqrt(double(count) / 2000)), 1, 64);
  const double cell = std::max(w, h) / double(base_side);
  for (uint64_t gy = 0; gy < base_side && instances.size() < count; ++gy) {
    for (uint64_t gx = 0; gx < base_side && instances.size() < count; ++gx) {
      BrushInstance base;
      base.brush = 0;
      base.x_px = (double(gx) + 0.5) * cell;
      base.y_px = (double(gy) + 0.5) * cell;
      base.radius_px = float(cell);
      base.rotation_rad = float(unit() * 6.283185307179586);
      base.layer = 0;
      instances.push_back(base);
    }
  }
  // Clusters of details: centres spread uniformly, instances normally around them.
  const uint64_t remaining = count - instances.size();
  const uint64_t clusters = std::max<uint64_t>(1, remaining / 200);
  std::vector<std::pair<double, double>> centres(clusters);
  for (auto& centre : centres) centre = {unit() * w, unit() * h};
  std::normal_distribution<double> spread(0, 1);
  while (instances.size() < count) {
    BrushInstance detail;
    const bool medium = rng() % 20 == 0;
    const auto& centre = centres[rng() % clusters];
    const double sigma = std::min(w, h) / 64;
    detail.x_px = std::clamp(centre.first + spread(rng) * sigma, 0.0, w);
    detail.y_px = std::clamp(centre.second + spread(rng) * sigma, 0.0, h);
    detail.brush = brush_count == 1 ? 0 : uint32_t(1 + rng() % (brush_count - 1));
    const double size = unit();
    detail.radius_px = float(medium ? 40 + size * 400 : 1 + size * size * 48);
    detail.rotation_rad = float(unit() * 6.283185307179586);
    detail.scale = float(0.75 + unit() * 0.5);
    detail.opacity = uint8_t(rng() % 4 == 0 ? 160 + rng() % 96 : 255);
    detail.tint_rgba =
        rng() % 3 == 0 ? 0xFF000000u | uint32_t(rng() & 0xFFFFFF) | 0x808080u : 0xFFFFFFFFu;
    detail.variant = uint8_t(rng() & 0xFF);
    detail.layer = medium ? 1 : 2 + int32_t(rng() % 3);
    instances.push_back(detail);
  }
  for (uint64_t i = 0; i < instances.size(); ++i) instances[i].id = i + 1;
  return instances;
}

}  // namespace tessera
