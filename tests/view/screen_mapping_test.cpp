// textureAt and levelOfDetailAt: the camera half of the sampling rules, with hand-worked points
// for orthographic and perspective views, and agreement with the runtime's footprint.
#include <tessera/view.h>

#include <cmath>
#include <limits>
#include <numbers>

#include <gtest/gtest.h>

#include "stream/residency.h"

namespace tessera {
namespace {

constexpr double kPi = std::numbers::pi;

View orthoView(double cx, double cy, double tpp, uint32_t w, uint32_t h, double rotation = 0) {
  View view;
  view.kind = View::Kind::kOrtho;
  view.ortho = {cx, cy, tpp, w, h, rotation};
  return view;
}

View perspectiveView(double ex, double ey, double ez, double yaw, double pitch, double fov,
                     uint32_t w, uint32_t h) {
  View view;
  view.kind = View::Kind::kPerspective;
  view.perspective = {ex, ey, ez, yaw, pitch, fov, w, h};
  return view;
}

struct Uv {
  double u = 0, v = 0;
  bool hit = false;
};

Uv at(const View& view, double sx, double sy) {
  Uv p;
  p.hit = textureAt(view, sx, sy, p.u, p.v);
  return p;
}

/// Screen-space size of one pixel at unit distance, worked by hand (tessera::pixelAngle).
double pixelAngle(double fov, uint32_t h) {
  return 2 * std::tan(fov / 2) / h;
}

TEST(ScreenMapping, OrthoPutsTheCentreMidScreenAtTheZoom) {
  const View view = orthoView(100, 50, 2, 8, 6);
  Uv p = at(view, 4, 3);
  EXPECT_TRUE(p.hit);
  EXPECT_DOUBLE_EQ(p.u, 100);
  EXPECT_DOUBLE_EQ(p.v, 50);
  p = at(view, 0, 0);  // (dx, dy) = (-4, -3), two texels each
  EXPECT_DOUBLE_EQ(p.u, 92);
  EXPECT_DOUBLE_EQ(p.v, 44);
  p = at(view, 7.5, 5.5);  // the last pixel's centre
  EXPECT_DOUBLE_EQ(p.u, 107);
  EXPECT_DOUBLE_EQ(p.v, 55);
}

TEST(ScreenMapping, OrthoRotationTurnsScreenXTowardsY) {
  // A quarter turn: u = cx - tpp dy, v = cy + tpp dx.
  View view = orthoView(100, 50, 3, 10, 10, kPi / 2);
  Uv p = at(view, 6, 5);  // one pixel right of the centre
  EXPECT_NEAR(p.u, 100, 1e-12);
  EXPECT_NEAR(p.v, 53, 1e-12);
  p = at(view, 5, 6);  // one pixel below it
  EXPECT_NEAR(p.u, 97, 1e-12);
  EXPECT_NEAR(p.v, 50, 1e-12);
  // 30 degrees, (dx, dy) = (2, 1), one texel per pixel:
  // u = 2 cos 30 - sin 30 = 1.2320508, v = 2 sin 30 + cos 30 = 1.8660254.
  view = orthoView(0, 0, 1, 10, 10, kPi / 6);
  p = at(view, 7, 6);
  EXPECT_NEAR(p.u, 1.2320508075688772, 1e-12);
  EXPECT_NEAR(p.v, 1.8660254037844386, 1e-12);
}

TEST(ScreenMapping, OrthoLevelOfDetailIsLog2OfTheZoomEverywhere) {
  for (double rotation : {0.0, 0.7}) {
    EXPECT_DOUBLE_EQ(levelOfDetailAt(orthoView(0, 0, 4, 16, 16, rotation), 0, 0), 2);
    EXPECT_DOUBLE_EQ(levelOfDetailAt(orthoView(0, 0, 4, 16, 16, rotation), 15, 9), 2);
    EXPECT_DOUBLE_EQ(levelOfDetailAt(orthoView(0, 0, 0.5, 16, 16, rotation), 3, 3), -1);
    EXPECT_NEAR(levelOfDetailAt(orthoView(0, 0, 3, 16, 16, rotation), 3, 3), std::log2(3.0), 1e-15);
  }
}

TEST(ScreenMapping, PerspectiveStraightDownIsLinearInPixels) {
  // Looking straight down with heading 0 (towards -y): screen right is +x, screen up is -y,
  // and one pixel is eye_z * pixelAngle texels.
  const double ez = 100, fov = 1.0;
  const View view = perspectiveView(500, 400, ez, 0, -kPi / 2, fov, 64, 48);
  const double step = ez * pixelAngle(fov, 48);
  for (double sx : {0.0, 10.5, 32.0, 63.5}) {
    for (double sy : {0.0, 7.25, 24.0, 47.5}) {
      const Uv p = at(view, sx, sy);
      ASSERT_TRUE(p.hit);
      EXPECT_NEAR(p.u, 500 + step * (sx - 32), 1e-9) << sx << "," << sy;
      EXPECT_NEAR(p.v, 400 + step * (sy - 24), 1e-9) << sx << "," << sy;
    }
  }
  for (uint32_t py : {0u, 23u, 47u})
    for (uint32_t px : {0u, 31u, 63u})
      EXPECT_NEAR(levelOfDetailAt(view, px, py), std::log2(step), 1e-9);
}

TEST(ScreenMapping, PerspectiveStraightDownFollowsTheHeading) {
  // Heading +x (yaw pi/2): the top of the screen is +x, its right +y.
  const View view = perspectiveView(0, 0, 50, kPi / 2, -kPi / 2, 0.8, 40, 40);
  const Uv centre = at(view, 20, 20), up = at(view, 20, 10), right = at(view, 30, 20);
  ASSERT_TRUE(centre.hit && up.hit && right.hit);
  EXPECT_NEAR(centre.u, 0, 1e-9);
  EXPECT_NEAR(centre.v, 0, 1e-9);
  EXPECT_GT(up.u, 1);
  EXPECT_NEAR(up.v, 0, 1e-9);
  EXPECT_NEAR(right.u, 0, 1e-9);
  EXPECT_GT(right.v, 1);
}

TEST(ScreenMapping, PerspectiveStraightDownMatchesTheOrthographicView) {
  // Same centre, zoom eye_z * pixelAngle: the two cameras see the same texels.
  const double ez = 300, fov = 0.9;
  const View persp = perspectiveView(1000, 700, ez, 0, -kPi / 2, fov, 32, 20);
  const View ortho = orthoView(1000, 700, ez * pixelAngle(fov, 20), 32, 20);
  for (double sx : {0.0, 5.5, 31.0})
    for (double sy : {0.0, 13.5, 20.0}) {
      const Uv a = at(persp, sx, sy), b = at(ortho, sx, sy);
      EXPECT_NEAR(a.u, b.u, 1e-9);
      EXPECT_NEAR(a.v, b.v, 1e-9);
    }
}

TEST(ScreenMapping, PerspectiveCentreRayHitsAlongTheHeading) {
  // The centre ray leaves the eye at the pitch: it lands eye_z / tan(-pitch) ahead.
  const double ez = 120, pitch = -0.7;
  View view = perspectiveView(10, 20, ez, 0, pitch, 1.0, 64, 48);
  Uv p = at(view, 32, 24);
  ASSERT_TRUE(p.hit);
  EXPECT_NEAR(p.u, 10, 1e-9);
  EXPECT_NEAR(p.v, 20 - ez / std::tan(-pitch), 1e-9);
  view.perspective.yaw_rad = kPi / 2;  // heading +x
  p = at(view, 32, 24);
  EXPECT_NEAR(p.u, 10 + ez / std::tan(-pitch), 1e-9);
  EXPECT_NEAR(p.v, 20, 1e-9);
}

TEST(ScreenMapping, PerspectiveTiltedLevelGrowsTowardsTheHorizonAndRaysAboveItMiss) {
  // Pitch -0.3 with a field of view of 1.0: the top half-angle reaches +0.2, above the
  // horizon; the bottom row looks 0.8 rad down.
  const View view = perspectiveView(0, 0, 100, 0, -0.3, 1.0, 64, 48);
  Uv top = at(view, 32, 0.5);
  EXPECT_FALSE(top.hit);
  EXPECT_EQ(levelOfDetailAt(view, 32, 0), std::numeric_limits<double>::infinity());
  // The horizon row: the ray at angle atan(ndc_y tan(0.5)) above the centre reaches the
  // pitch's 0.3 rad at ndc_y = tan(0.3) / tan(0.5).
  const double horizon_sy = 24 * (1 - std::tan(0.3) / std::tan(0.5));
  EXPECT_FALSE(at(view, 32, horizon_sy - 0.01).hit);
  EXPECT_TRUE(at(view, 32, horizon_sy + 0.01).hit);
  double previous_lambda = -std::numeric_limits<double>::infinity();
  double previous_v = 0;
  int rows_hit = 0;
  for (int py = 47; py >= 0; --py) {  // bottom to top: further away
    Uv p = at(view, 32.5, py + 0.5);
    if (!p.hit) {
      EXPECT_LT(py + 0.5, horizon_sy);
      EXPECT_EQ(levelOfDetailAt(view, 32, uint32_t(py)), std::numeric_limits<double>::infinity());
      continue;
    }
    const double lambda = levelOfDetailAt(view, 32, uint32_t(py));
    EXPECT_GT(lambda, previous_lambda) << py;
    if (rows_hit > 0) {
      EXPECT_LT(p.v, previous_v) << py;  // further along -y
    }
    previous_lambda = lambda;
    previous_v = p.v;
    ++rows_hit;
  }
  EXPECT_GT(rows_hit, 20);
}

TEST(ScreenMapping, PerspectiveLevelMatchesCentralDifferences) {
  const View view = perspectiveView(-40, 75, 80, 0.6, -0.5, 1.1, 96, 64);
  for (uint32_t py : {20u, 40u, 63u}) {
    for (uint32_t px : {0u, 50u, 95u}) {
      const double sx = px + 0.5, sy = py + 0.5, h = 1e-3;
      const Uv l = at(view, sx - h, sy), r = at(view, sx + h, sy);
      const Uv t = at(view, sx, sy - h), b = at(view, sx, sy + h);
      ASSERT_TRUE(l.hit && r.hit && t.hit && b.hit);
      const double rho_x = std::hypot(r.u - l.u, r.v - l.v) / (2 * h);
      const double rho_y = std::hypot(b.u - t.u, b.v - t.v) / (2 * h);
      EXPECT_NEAR(levelOfDetailAt(view, px, py), std::log2(std::max(rho_x, rho_y)), 1e-5)
          << px << "," << py;
    }
  }
}

TEST(ScreenMapping, EyeBelowThePlaneSeesNothing) {
  const View view = perspectiveView(0, 0, -5, 0, -0.8, 1.0, 16, 16);
  EXPECT_FALSE(at(view, 8, 15).hit);
  EXPECT_EQ(levelOfDetailAt(view, 8, 15), std::numeric_limits<double>::infinity());
}

ImageInfo squareImage(uint32_t side_px, uint32_t tile_px, uint32_t levels) {
  ImageInfo info;
  info.width_px = info.height_px = side_px;
  info.channels = 3;
  info.tile_size_px = tile_px;
  info.level_count = levels;
  return info;
}

TEST(ScreenMapping, StraightDownLevelIsTheFootprintsDesiredLevel) {
  // eye_z * pixelAngle = 5 texels per pixel: lambda = log2(5) = 2.32, level 2.
  const ImageInfo info = squareImage(8192, 256, 6);
  const double fov = 1.0;
  const double ez = 5 / pixelAngle(fov, 48);
  const View view = perspectiveView(4000, 4000, ez, 0.3, -kPi / 2, fov, 64, 48);
  const detail::Footprint footprint = detail::footprintOf(view, info);
  EXPECT_EQ(footprint.desired_level, 2u);
  EXPECT_NEAR(levelOfDetailAt(view, 32, 24), std::log2(5.0), 1e-9);
  EXPECT_EQ(uint32_t(std::floor(levelOfDetailAt(view, 32, 24))), footprint.desired_level);
  // Orthographic: the same rule from the zoom.
  const View ortho = orthoView(4000, 4000, 5, 64, 48);
  EXPECT_EQ(uint32_t(std::floor(levelOfDetailAt(ortho, 0, 0))),
            detail::footprintOf(ortho, info).desired_level);
}

TEST(ScreenMapping, TiltedViewNeverNeedsFinerThanTheFootprintsLevel) {
  // The runtime loads the footprint's desired level as its finest: no pixel may ask for
  // finer, and some pixel asks for exactly that level.
  const ImageInfo info = squareImage(65536, 256, 9);
  const View view = perspectiveView(30000, 30000, 400, 1.1, -0.6, 1.0, 160, 90);
  const uint32_t desired = detail::footprintOf(view, info).desired_level;
  uint32_t finest = UINT32_MAX;
  for (uint32_t py = 0; py < 90; ++py) {
    for (uint32_t px = 0; px < 160; ++px) {
      const double lambda = levelOfDetailAt(view, px, py);
      if (std::isinf(lambda)) continue;
      const uint32_t level = lambda < 0 ? 0 : uint32_t(std::floor(lambda));
      EXPECT_GE(level, desired) << px << "," << py;
      finest = std::min(finest, level);
    }
  }
  EXPECT_LE(finest, desired + 1);
}

}  // namespace
}  // namespace tessera
