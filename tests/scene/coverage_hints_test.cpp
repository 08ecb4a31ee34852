// The coverage hints' CPU rasterizer and builder (docs/scenes.md, "Coverage hints") against a
// brute-force reference written independently: a ray cast through every pixel centre against
// every triangle (Moller-Trumbore in double precision), nearest hit in front of the near plane.
// The two must agree on every pixel except where the answer hangs on rounding: a pixel centre
// within 1e-7 (barycentric) of a triangle's edge, a hit within 1e-7 (relative) of the near
// plane, or two hits within 1e-7 (relative) in depth (interpenetrating triangles). Those
// pixels are counted, must be rare, and bound the difference of the counts.
#include <algorithm>
#include <cmath>
#include <map>
#include <random>

#include <gtest/gtest.h>

#include "hint_builder.h"
#include "id_raster.h"

namespace tessera::detail {
namespace {

constexpr double kEdgeEps = 1e-7;

struct RayHit {
  uint32_t id = kNoId;
  bool ambiguous = false;
};

// The reference: what the pixel centre's ray sees.
RayHit castRay(const RasterCamera& c, uint32_t i, uint32_t j, const std::vector<float>& tris,
               const std::vector<uint32_t>& ids) {
  const double sx = c.tan_half_x * (2 * (i + 0.5) / c.width - 1);
  const double sy = c.tan_half_y * (1 - 2 * (j + 0.5) / c.height);
  double dir[3];
  for (int a = 0; a < 3; ++a) dir[a] = c.forward[a] + c.right[a] * sx + c.up[a] * sy;
  struct Hit {
    double t;
    uint32_t id;
  };
  std::vector<Hit> strict, loose;  // centre inside; centre inside or within kEdgeEps of it
  for (size_t k = 0; k < ids.size(); ++k) {
    double p[3][3];
    for (int v = 0; v < 3; ++v)
      for (int a = 0; a < 3; ++a) p[v][a] = tris[9 * k + 3 * v + a];
    double e1[3], e2[3], s[3];
    for (int a = 0; a < 3; ++a) {
      e1[a] = p[1][a] - p[0][a];
      e2[a] = p[2][a] - p[0][a];
      s[a] = c.eye[a] - p[0][a];
    }
    auto cross = [](const double* x, const double* y, double* r) {
      r[0] = x[1] * y[2] - x[2] * y[1];
      r[1] = x[2] * y[0] - x[0] * y[2];
      r[2] = x[0] * y[1] - x[1] * y[0];
    };
    auto dot = [](const double* x, const double* y) {
      return x[0] * y[0] + x[1] * y[1] + x[2] * y[2];
    };
    double pv[3], qv[3];
    cross(dir, e2, pv);
    const double det = dot(e1, pv);
    if (det == 0) continue;  // the ray runs along the triangle's plane
    const double u = dot(s, pv) / det;
    cross(s, e1, qv);
    const double v = dot(dir, qv) / det;
    const double t = dot(e2, qv) / det;  // camera depth: dir . forward == 1
    const double margin = std::min({u, v, 1 - u - v});
    if (margin > -kEdgeEps && t >= c.near * (1 - kEdgeEps)) loose.push_back({t, ids[k]});
    if (margin >= 0 && t >= c.near) strict.push_back({t, ids[k]});
  }
  RayHit out;
  double nearest = INFINITY;
  for (const Hit& h : strict) {
    if (h.t < nearest || (h.t == nearest && h.id < out.id)) {
      nearest = h.t;
      out.id = h.id;
    }
  }
  // Ambiguous when a triangle with another ID could be the nearest under rounding.
  for (const Hit& h : loose)
    if (h.id != out.id && h.t <= nearest * (1 + kEdgeEps)) out.ambiguous = true;
  return out;
}

// Triangles scattered around the origin, some through the camera's near plane and behind it.
void randomTriangles(std::mt19937& rng, uint32_t count, std::vector<float>& tris,
                     std::vector<uint32_t>& ids) {
  std::uniform_real_distribution<float> centre(-4, 4), offset(-1.5f, 1.5f);
  for (uint32_t k = 0; k < count; ++k) {
    const float cx = centre(rng), cy = centre(rng), cz = centre(rng);
    for (int v = 0; v < 3; ++v) {
      tris.push_back(cx + offset(rng));
      tris.push_back(cy + offset(rng));
      tris.push_back(cz + offset(rng));
    }
    ids.push_back(k % 7 == 3 ? 2 : k);  // some IDs shared by several triangles
  }
}

TEST(IdRaster, MatchesPerPixelRayCastOnRandomScenes) {
  std::mt19937 rng(28);
  uint64_t pixels = 0, ambiguous = 0, drawn = 0;
  for (int scene = 0; scene < 12; ++scene) {
    std::vector<float> tris;
    std::vector<uint32_t> ids;
    randomTriangles(rng, 60, tris, ids);
    std::uniform_real_distribution<double> eye(-1, 1);
    std::vector<RasterCamera> cameras;
    for (const RasterCamera& face : cubeFaceCameras({eye(rng), eye(rng), eye(rng)}, 48, 0.05))
      cameras.push_back(face);
    RasterCamera wide = cameras[0];  // a non-square, non-90-degree view as well
    wide.width = 61;
    wide.height = 37;
    wide.tan_half_x = 1.7;
    wide.tan_half_y = 0.6;
    cameras.push_back(wide);
    for (const RasterCamera& camera : cameras) {
      IdBuffer buffer;
      buffer.reset(camera);
      rasterizeTriangles(camera, tris, ids, buffer);
      std::map<uint32_t, int64_t> difference;
      uint64_t ambiguous_here = 0;
      for (uint32_t j = 0; j < camera.height; ++j) {
        for (uint32_t i = 0; i < camera.width; ++i) {
          const RayHit hit = castRay(camera, i, j, tris, ids);
          const uint32_t got = buffer.ids[size_t(j) * camera.width + i];
          ++pixels;
          drawn += got != kNoId;
          ++difference[got];
          --difference[hit.id];
          if (hit.ambiguous) {
            ++ambiguous_here;
            continue;
          }
          ASSERT_EQ(got, hit.id) << "scene " << scene << " pixel (" << i << ", " << j << ")";
        }
      }
      ambiguous += ambiguous_here;
      for (const auto& [id, diff] : difference) EXPECT_LE(uint64_t(std::abs(diff)), ambiguous_here);
    }
  }
  EXPECT_GT(drawn, pixels / 4) << "the scenes should cover a good part of the views";
  EXPECT_LT(ambiguous, pixels / 100) << "ambiguous pixels must stay rare for the test to mean much";
}

TEST(IdRaster, SharedEdgeGoesToExactlyOneTriangle) {
  // Two triangles of a square whose diagonal passes exactly through pixel centres.
  RasterCamera camera = cubeFaceCameras({0, 0, 0}, 8, 0.01)[4];  // looking along +z
  const float z = 1;
  const std::vector<float> tris = {-1, -1, z, 1, -1, z, 1, 1, z, -1, -1, z, 1, 1, z, -1, 1, z};
  IdBuffer buffer;
  buffer.reset(camera);
  rasterizeTriangles(camera, tris, std::vector<uint32_t>{0, 1}, buffer);
  for (uint32_t id : buffer.ids) EXPECT_NE(id, kNoId);  // no gaps along the diagonal
  IdBuffer one;
  one.reset(camera);
  rasterizeTriangles(camera, std::span(tris).subspan(0, 9), std::vector<uint32_t>{0}, one);
  IdBuffer other;
  other.reset(camera);
  rasterizeTriangles(camera, std::span(tris).subspan(9, 9), std::vector<uint32_t>{1}, other);
  for (size_t p = 0; p < buffer.ids.size(); ++p)
    EXPECT_FALSE(one.ids[p] != kNoId && other.ids[p] != kNoId) << "pixel " << p << " drawn twice";
}

// Boxes (12 triangles each) on a ground quad, with textures in several slots.
HintScene randomBoxes(std::mt19937& rng, uint32_t boxes, uint32_t textures) {
  HintScene scene;
  scene.texture_count = textures;
  scene.object_first.push_back(0);
  std::uniform_real_distribution<float> pos(0, 20), size(0.5f, 4);
  std::uniform_int_distribution<uint32_t> texture(0, textures - 1);
  scene.bounds.min = {0, 0, 0};
  scene.bounds.max = {0, 0, 0};
  for (uint32_t b = 0; b < boxes; ++b) {
    SceneBox box;
    const float x = pos(rng), z = pos(rng), w = size(rng), h = 2 * size(rng), d = size(rng);
    box.min = {x, 0, z};
    box.max = {x + w, h, z + d};
    if (b == 0) box = {{-2, -0.2f, -2}, {24, -0.01f, 24}};  // the ground, below the boxes
    for (int face = 0; face < 6; ++face) {
      const int axis = face / 2;
      const float at = face % 2 ? box.max[axis] : box.min[axis];
      const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
      float q[4][3];
      for (int c = 0; c < 4; ++c) {
        q[c][axis] = at;
        q[c][a1] = (c == 1 || c == 2) ? box.max[a1] : box.min[a1];
        q[c][a2] = (c >= 2) ? box.max[a2] : box.min[a2];
      }
      for (int k : {0, 1, 2, 0, 2, 3})
        scene.triangles.insert(scene.triangles.end(), q[k], q[k] + 3);
    }
    scene.object_first.push_back(uint32_t(scene.triangles.size() / 9));
    scene.object_bounds.push_back(box);
    std::array<uint32_t, kSceneTextureSlots> slots;
    slots.fill(kNoSceneTexture);
    slots[0] = texture(rng);
    if (b % 3 == 1) slots[2] = texture(rng);      // a normal map too
    if (b % 5 == 2) slots[4] = slots[0];          // the same texture twice: credited once
    if (b % 11 == 7) slots[0] = kNoSceneTexture;  // untextured: occludes, counts for nothing
    scene.object_textures.push_back(slots);
    for (int a = 0; a < 3; ++a) {
      scene.bounds.min[a] = std::min(scene.bounds.min[a], box.min[a]);
      scene.bounds.max[a] = std::max(scene.bounds.max[a], box.max[a]);
    }
  }
  return scene;
}

TEST(CoverageHints, BuilderMatchesBruteForcePixelCount) {
  std::mt19937 rng(3);
  const HintScene scene = randomBoxes(rng, 30, 9);
  HintBuildOptions options;
  options.cell_size = 13;  // 2 x 2 cells
  options.resolution_px = 16;
  options.threads = 2;
  options.min_object_px = 0;
  auto hints = buildCoverageHints(scene, options);
  ASSERT_TRUE(hints) << hints.error().message;
  ASSERT_EQ(hints->cellCount(), 4u);
  const std::vector<double> weights = facePixelSolidAngles(options.resolution_px);
  double face = 0;
  for (double w : weights) face += w;
  EXPECT_NEAR(face * 6, 4 * M_PI, 1e-9) << "pixel solid angles cover the sphere";
  std::vector<uint32_t> ids;
  for (uint32_t o = 0; o < scene.objectCount(); ++o)
    for (uint32_t k = scene.object_first[o]; k < scene.object_first[o + 1]; ++k) ids.push_back(o);
  uint64_t compared = 0;
  for (uint32_t cell = 0; cell < 4; ++cell) {
    std::vector<double> texture(scene.texture_count, 0);
    double ambiguous = 0;
    const auto eyes = cellEyePositions(*hints, cell);
    ASSERT_EQ(eyes.size(), 8u);
    for (const auto& eye : eyes) {
      for (const RasterCamera& camera :
           cubeFaceCameras(eye, options.resolution_px, hints->cell_size * 1e-4)) {
        for (uint32_t p = 0; p < weights.size(); ++p) {
          const RayHit hit = castRay(camera, p % options.resolution_px, p / options.resolution_px,
                                     scene.triangles, ids);
          if (hit.ambiguous) ambiguous += weights[p];
          if (hit.id == kNoId) continue;
          const auto& slots = scene.object_textures[hit.id];
          for (uint32_t k = 0; k < kSceneTextureSlots; ++k)
            if (slots[k] != kNoSceneTexture &&
                std::find(slots.begin(), slots.begin() + k, slots[k]) == slots.begin() + k)
              texture[slots[k]] += weights[p];
        }
      }
    }
    const double sphere = 8 * 4 * M_PI;
    const double tolerance_q = ambiguous / sphere * 65535 + 1;  // + 1: rounding of either side
    std::map<uint32_t, uint16_t> got;
    for (const CoverageHint& e : hints->cell(cell)) got[e.texture] = e.coverage_q;
    for (uint32_t t = 0; t < scene.texture_count; ++t) {
      const double expected = texture[t] > 0 ? quantiseCoverage(texture[t] / sphere) : 0;
      EXPECT_NEAR(double(got.count(t) ? got[t] : 0), expected, tolerance_q)
          << "cell " << cell << " texture " << t;
      compared += expected > 0;
    }
    EXPECT_LT(ambiguous, sphere / 100);
  }
  EXPECT_GT(compared, 8u);
}

TEST(CoverageHints, ThreadCountChangesNothingAndTheDefaultGridIs16Cells) {
  std::mt19937 rng(5);
  const HintScene scene = randomBoxes(rng, 40, 6);
  HintBuildOptions options;
  options.resolution_px = 8;
  options.threads = 1;
  auto one = buildCoverageHints(scene, options);
  options.threads = 3;
  auto three = buildCoverageHints(scene, options);
  ASSERT_TRUE(one && three);
  EXPECT_EQ(*one, *three);
  EXPECT_EQ(one->cellCount(), 16u * 16u) << "the default grid: 16 cells on the longer side";
}

TEST(CoverageHints, RefusesBadOptions) {
  std::mt19937 rng(7);
  const HintScene scene = randomBoxes(rng, 3, 2);
  HintBuildOptions options;
  options.resolution_px = 0;
  EXPECT_FALSE(buildCoverageHints(scene, options));
  options.resolution_px = 16;
  options.cell_size = -1;
  EXPECT_FALSE(buildCoverageHints(scene, options));
}

}  // namespace
}  // namespace tessera::detail
