#include "hint_builder.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <thread>

#include <fmt/format.h>

#include "format/coverage_hints.h"
#include "id_raster.h"

namespace tessera::detail {

namespace {

constexpr uint32_t kAutoCellsPerSide = 16;

double distanceToBox(const std::array<double, 3>& p, const SceneBox& box) {
  double sum = 0;
  for (int a = 0; a < 3; ++a) {
    const double out = std::max({0.0, box.min[a] - p[a], p[a] - box.max[a]});
    sum += out * out;
  }
  return std::sqrt(sum);
}

struct Sphere {
  std::array<double, 3> centre;
  double radius;
};

Sphere sphereOf(const SceneBox& box) {
  Sphere s;
  double r2 = 0;
  for (int a = 0; a < 3; ++a) {
    s.centre[a] = (double(box.min[a]) + box.max[a]) / 2;
    const double half = (double(box.max[a]) - box.min[a]) / 2;
    r2 += half * half;
  }
  s.radius = std::sqrt(r2);
  return s;
}

// Objects grouped by the hint cell of their centre, with the group's box and largest radius,
// so a view position skips whole groups too far away to draw anything (min_object_px).
struct ObjectGroups {
  std::vector<std::vector<uint32_t>> objects;
  std::vector<SceneBox> bounds;
  std::vector<double> max_radius;
};

ObjectGroups groupObjects(const HintScene& scene, const CoverageHints& grid) {
  ObjectGroups g;
  const uint32_t cells = grid.cellCount();
  g.objects.resize(cells);
  g.bounds.assign(cells, SceneBox{});
  g.max_radius.assign(cells, 0);
  for (uint32_t o = 0; o < scene.objectCount(); ++o) {
    const Sphere s = sphereOf(scene.object_bounds[o]);
    const int64_t c = grid.cellAt(s.centre.data());
    const uint32_t cell = uint32_t(std::max<int64_t>(0, c));
    SceneBox& box = g.bounds[cell];
    if (g.objects[cell].empty()) box = scene.object_bounds[o];
    for (int a = 0; a < 3; ++a) {
      box.min[a] = std::min(box.min[a], scene.object_bounds[o].min[a]);
      box.max[a] = std::max(box.max[a], scene.object_bounds[o].max[a]);
    }
    g.max_radius[cell] = std::max(g.max_radius[cell], s.radius);
    g.objects[cell].push_back(o);
  }
  return g;
}

// False when the sphere lies wholly outside the 90-degree face (behind it or past a side).
bool sphereMeetsFace(const RasterCamera& face, const Sphere& s) {
  const double d[3] = {s.centre[0] - face.eye[0], s.centre[1] - face.eye[1],
                       s.centre[2] - face.eye[2]};
  double x = 0, y = 0, z = 0;
  for (int a = 0; a < 3; ++a) {
    x += face.right[a] * d[a];
    y += face.up[a] * d[a];
    z += face.forward[a] * d[a];
  }
  // Side planes x = +-z and y = +-z; their unit normals are (+-1, 0, -1) / sqrt 2.
  const double r = s.radius * std::sqrt(2.0);
  return z >= -s.radius && x - z <= r && -x - z <= r && y - z <= r && -y - z <= r;
}

// What one worker keeps between cells.
struct CellScratch {
  IdBuffer buffer;
  std::vector<uint32_t> ids;
  std::vector<double> object_weight;  ///< per object, this cell's weighted pixels
  std::vector<uint32_t> touched;      ///< objects with a non-zero weight
  std::vector<double> texture_weight;
  std::vector<uint32_t> candidates;
  std::vector<double> distances;  ///< per object, from the current eye
  HintBuildStats stats;
};

class HintJob {
 public:
  HintJob(const HintScene& scene, const HintBuildOptions& options, const CoverageHints& grid)
      : scene_(scene),
        options_(options),
        grid_(grid),
        groups_(groupObjects(scene, grid)),
        weights_(facePixelSolidAngles(options.resolution_px)) {
    for (uint32_t o = 0; o < scene.objectCount(); ++o)
      spheres_.push_back(sphereOf(scene.object_bounds[o]));
  }

  // The textures seen from `cell`, in increasing order, with their shares of the sphere.
  std::vector<CoverageHint> cell(uint32_t cell, CellScratch& s) const {
    s.object_weight.resize(scene_.objectCount(), 0);
    s.texture_weight.resize(scene_.texture_count, 0);
    const std::vector<std::array<double, 3>> eyes = cellEyePositions(grid_, cell);
    const double near = grid_.cell_size * 1e-4;
    for (const std::array<double, 3>& eye : eyes) {
      collectCandidates(eye, s);
      for (const RasterCamera& face : cubeFaceCameras(eye, options_.resolution_px, near))
        drawFace(face, s);
    }
    for (uint32_t o : s.touched) {
      const auto& slots = scene_.object_textures[o];
      for (uint32_t k = 0; k < kSceneTextureSlots; ++k) {
        const uint32_t t = slots[k];
        // An object using one texture in two slots is credited once.
        if (t == kNoSceneTexture ||
            std::find(slots.begin(), slots.begin() + k, t) != slots.begin() + k)
          continue;
        s.texture_weight[t] += s.object_weight[o];
      }
      s.object_weight[o] = 0;
    }
    s.touched.clear();
    // Normalised by the whole sampled sphere of every position (4 pi each, as summed).
    double sphere = 0;
    for (double w : weights_) sphere += w;
    sphere *= 6.0 * double(eyes.size());
    std::vector<CoverageHint> out;
    for (uint32_t t = 0; t < scene_.texture_count; ++t) {
      if (s.texture_weight[t] == 0) continue;
      out.push_back({t, quantiseCoverage(s.texture_weight[t] / sphere)});
      s.texture_weight[t] = 0;
    }
    return out;
  }

 private:
  void collectCandidates(const std::array<double, 3>& eye, CellScratch& s) const {
    s.candidates.clear();
    // A sphere of radius r at distance d spans about 2 r / d radians; a face pixel at the
    // centre spans 2 / resolution.
    const double min_ratio = options_.min_object_px / options_.resolution_px;
    for (size_t g = 0; g < groups_.objects.size(); ++g) {
      if (groups_.objects[g].empty()) continue;
      const double d = distanceToBox(eye, groups_.bounds[g]);
      if (d > 0 && groups_.max_radius[g] < min_ratio * d) continue;
      for (uint32_t o : groups_.objects[g]) {
        const Sphere& sphere = spheres_[o];
        const double dx = sphere.centre[0] - eye[0], dy = sphere.centre[1] - eye[1],
                     dz = sphere.centre[2] - eye[2];
        const double dc = std::sqrt(dx * dx + dy * dy + dz * dz);
        if (dc > sphere.radius && sphere.radius < min_ratio * dc) continue;
        s.candidates.push_back(o);
      }
    }
    // Front to back, so that boxHidden skips what nearer objects already cover.
    s.distances.resize(scene_.objectCount());
    for (uint32_t o : s.candidates) s.distances[o] = distanceToBox(eye, scene_.object_bounds[o]);
    std::sort(s.candidates.begin(), s.candidates.end(), [&](uint32_t a, uint32_t b) {
      return s.distances[a] != s.distances[b] ? s.distances[a] < s.distances[b] : a < b;
    });
  }

  void drawFace(const RasterCamera& face, CellScratch& s) const {
    s.buffer.reset(face);
    ++s.stats.views;
    for (uint32_t o : s.candidates) {
      if (!sphereMeetsFace(face, spheres_[o])) continue;
      const SceneBox& box = scene_.object_bounds[o];
      if (boxHidden(face, box.min, box.max, s.buffer)) continue;
      ++s.stats.objects_drawn;
      const uint32_t first = scene_.object_first[o], count = scene_.object_first[o + 1] - first;
      s.ids.assign(count, o);
      rasterizeTriangles(face, std::span(scene_.triangles).subspan(size_t(first) * 9, count * 9),
                         s.ids, s.buffer);
    }
    for (size_t p = 0; p < s.buffer.ids.size(); ++p) {
      const uint32_t o = s.buffer.ids[p];
      if (o == kNoId) continue;
      if (s.object_weight[o] == 0) s.touched.push_back(o);
      s.object_weight[o] += weights_[p];
    }
  }

  const HintScene& scene_;
  const HintBuildOptions& options_;
  const CoverageHints& grid_;
  ObjectGroups groups_;
  std::vector<double> weights_;
  std::vector<Sphere> spheres_;
};

}  // namespace

uint16_t quantiseCoverage(double share) {
  return uint16_t(std::clamp<double>(std::round(share * 65535.0), 1.0, 65535.0));
}

std::vector<double> facePixelSolidAngles(uint32_t resolution_px) {
  // The solid angle of [0, x] x [0, y] on the plane at distance 1 is atan(x y / sqrt(x^2 + y^2
  // + 1)); a pixel's is the inclusion-exclusion of its four corners, exact.
  auto corner = [](double x, double y) { return std::atan2(x * y, std::sqrt(x * x + y * y + 1)); };
  std::vector<double> out(size_t(resolution_px) * resolution_px);
  const double step = 2.0 / resolution_px;
  for (uint32_t j = 0; j < resolution_px; ++j) {
    const double y0 = -1 + j * step, y1 = y0 + step;
    for (uint32_t i = 0; i < resolution_px; ++i) {
      const double x0 = -1 + i * step, x1 = x0 + step;
      out[size_t(j) * resolution_px + i] =
          corner(x1, y1) - corner(x0, y1) - corner(x1, y0) + corner(x0, y0);
    }
  }
  return out;
}

CoverageHints hintGrid(const HintScene& scene, const HintBuildOptions& options) {
  CoverageHints grid;
  grid.up_axis = options.up_axis;
  grid.texture_count = scene.texture_count;
  grid.resolution_px = options.resolution_px;
  const uint32_t u = grid.axisU(), v = grid.axisV(), up = grid.up_axis;
  const double extent_u = double(scene.bounds.max[u]) - scene.bounds.min[u];
  const double extent_v = double(scene.bounds.max[v]) - scene.bounds.min[v];
  double size =
      options.cell_size > 0 ? options.cell_size : std::max(extent_u, extent_v) / kAutoCellsPerSide;
  if (!(size > 0)) size = 1;
  // Never more cells than the format allows: a finer request is coarsened.
  while (std::ceil(extent_u / size) * std::ceil(extent_v / size) > kMaxHintCells ||
         std::ceil(std::max(extent_u, extent_v) / size) > kMaxHintCellsPerAxis)
    size *= 2;
  grid.cell_size = float(size);
  grid.cells_u = std::max(1u, uint32_t(std::ceil(extent_u / grid.cell_size)));
  grid.cells_v = std::max(1u, uint32_t(std::ceil(extent_v / grid.cell_size)));
  grid.origin_u = scene.bounds.min[u];
  grid.origin_v = scene.bounds.min[v];
  // Eye heights: the octant centres of the lower half of the scene's height (at least a cell
  // high), i.e. 1/8 and 3/8 of it above the ground: street level up to the roofs of a city.
  const double ground = scene.bounds.min[up];
  const double height = std::max(double(scene.bounds.max[up]) - ground, size);
  grid.eye_low = float(ground + height / 8);
  grid.eye_high = float(ground + 3 * height / 8);
  grid.cell_first.assign(grid.cellCount() + 1, 0);
  return grid;
}

std::vector<std::array<double, 3>> cellEyePositions(const CoverageHints& grid, uint32_t cell) {
  const uint32_t i = cell % grid.cells_u, j = cell / grid.cells_u;
  std::vector<std::array<double, 3>> out;
  for (double h : {double(grid.eye_low), double(grid.eye_high)}) {
    for (double fv : {0.25, 0.75}) {
      for (double fu : {0.25, 0.75}) {
        std::array<double, 3> p{};
        p[grid.axisU()] = grid.origin_u + (i + fu) * double(grid.cell_size);
        p[grid.axisV()] = grid.origin_v + (j + fv) * double(grid.cell_size);
        p[grid.up_axis] = h;
        out.push_back(p);
      }
    }
  }
  return out;
}

Result<CoverageHints> buildCoverageHints(const HintScene& scene, const HintBuildOptions& options,
                                         HintBuildStats* stats) {
  const auto start = std::chrono::steady_clock::now();
  if (options.resolution_px < 1 || options.resolution_px > kMaxHintResolutionPx ||
      options.up_axis > 2 || !(options.cell_size >= 0) || !(options.min_object_px >= 0))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("coverage hints: resolution {} px out of 1..{}, or a negative cell "
                            "size or object size",
                            options.resolution_px, kMaxHintResolutionPx));
  if (scene.texture_count > 65536)
    return fail(ErrorCode::kTooLarge, "coverage hints: more than 65536 textures");
  CoverageHints hints = hintGrid(scene, options);
  const HintJob job(scene, options, hints);
  const uint32_t cells = hints.cellCount();
  std::vector<std::vector<CoverageHint>> per_cell(cells);
  std::atomic<uint32_t> next{0};
  const uint32_t threads = std::clamp(options.threads, 1u, cells);
  std::vector<CellScratch> scratch(threads);
  auto work = [&](CellScratch& s) {
    for (uint32_t c = next++; c < cells; c = next++) per_cell[c] = job.cell(c, s);
  };
  std::vector<std::thread> pool;
  for (uint32_t t = 1; t < threads; ++t) pool.emplace_back(work, std::ref(scratch[t]));
  work(scratch[0]);
  for (std::thread& thread : pool) thread.join();
  for (uint32_t c = 0; c < cells; ++c) {
    hints.cell_first[c] = uint32_t(hints.entries.size());
    hints.entries.insert(hints.entries.end(), per_cell[c].begin(), per_cell[c].end());
  }
  hints.cell_first[cells] = uint32_t(hints.entries.size());
  if (stats) {
    *stats = {};
    for (const CellScratch& s : scratch) {
      stats->views += s.stats.views;
      stats->objects_drawn += s.stats.objects_drawn;
    }
    stats->seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return hints;
}

}  // namespace tessera::detail
