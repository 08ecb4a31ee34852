// The camera every module shares: its basis, its rays and its projection, which must put each
// texel on the pixel that textureAt says sees it.
#include <tessera/view.h>

#include <cmath>
#include <vector>

#include <gtest/gtest.h>

namespace tessera {
namespace {

double dot(const Vec3& a, const Vec3& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}

PerspectiveView camera(double yaw, double pitch) {
  PerspectiveView p;
  p.eye_x = 500;
  p.eye_y = 700;
  p.eye_z = 180;
  p.yaw_rad = yaw;
  p.pitch_rad = pitch;
  p.viewport_w = 160;
  p.viewport_h = 120;
  return p;
}

TEST(Camera, BasisIsOrthonormalWithUpForwardCrossRight) {
  for (double yaw : {0.0, 0.4, -2.0, 3.0})
    for (double pitch : {-0.1, -0.55, -1.5}) {
      const CameraBasis b = cameraBasis(camera(yaw, pitch));
      EXPECT_NEAR(dot(b.forward, b.forward), 1, 1e-12);
      EXPECT_NEAR(dot(b.right, b.right), 1, 1e-12);
      EXPECT_NEAR(dot(b.up, b.up), 1, 1e-12);
      EXPECT_NEAR(dot(b.forward, b.right), 0, 1e-12);
      EXPECT_NEAR(dot(b.forward, b.up), 0, 1e-12);
      EXPECT_NEAR(dot(b.right, b.up), 0, 1e-12);
      // A camera below the horizon has its screen's top row looking further out: up climbs.
      EXPECT_GT(b.up.z, 0);
    }
}

TEST(Camera, YawZeroLooksUpTheImageWithScreenXAlongX) {
  const CameraBasis b = cameraBasis(camera(0, 0));
  EXPECT_NEAR(b.forward.y, -1, 1e-12);
  EXPECT_NEAR(b.right.x, 1, 1e-12);
  EXPECT_NEAR(b.up.z, 1, 1e-12);
}

TEST(Camera, RollTurnsRightTowardsUpAboutForward) {
  PerspectiveView p = camera(0.7, -0.6);
  const CameraBasis flat = cameraBasis(p);
  p.roll_rad = 0.5;
  const CameraBasis rolled = cameraBasis(p);
  EXPECT_NEAR(dot(rolled.forward, flat.forward), 1, 1e-12);
  EXPECT_NEAR(dot(rolled.right, flat.right), std::cos(0.5), 1e-12);
  EXPECT_NEAR(dot(rolled.right, flat.up), std::sin(0.5), 1e-12);
  EXPECT_NEAR(dot(rolled.up, flat.up), std::cos(0.5), 1e-12);
  EXPECT_NEAR(dot(rolled.right, rolled.up), 0, 1e-12);
  EXPECT_NEAR(dot(rolled.forward, rolled.right), 0, 1e-12);
}

TEST(Camera, RayThroughTheScreenCentreIsForwardAndCornersSpanTheFieldOfView) {
  const PerspectiveView p = camera(0.7, -0.6);
  const CameraBasis b = cameraBasis(p);
  const Vec3 centre = rayDirection(p, 0, 0);
  EXPECT_NEAR(centre.x, b.forward.x, 1e-12);
  EXPECT_NEAR(centre.y, b.forward.y, 1e-12);
  EXPECT_NEAR(centre.z, b.forward.z, 1e-12);
  const Vec3 top = rayDirection(p, 0, 1);
  const double angle = std::acos(dot(top, b.forward) / std::sqrt(dot(top, top)));
  EXPECT_NEAR(angle, p.fov_y_rad / 2, 1e-12);
}

TEST(Camera, PixelAngleIsTheFieldOfViewOverTheHeight) {
  PerspectiveView p = camera(0, -1);
  EXPECT_DOUBLE_EQ(pixelAngle(p), 2 * std::tan(0.5) / 120);
  p.viewport_h = 0;  // read as one pixel
  EXPECT_DOUBLE_EQ(pixelAngle(p), 2 * std::tan(0.5));
}

TEST(Camera, ANonPositiveZoomReadsAsOne) {
  OrthoView o;
  o.texels_per_pixel = 0;
  EXPECT_EQ(texelsPerPixelOf(o), 1);
  o.texels_per_pixel = std::nan("");
  EXPECT_EQ(texelsPerPixelOf(o), 1);
  o.texels_per_pixel = 2.5;
  EXPECT_EQ(texelsPerPixelOf(o), 2.5);
}

/// Where the projection puts level-0 texel (u, v), in screen pixels.
bool project(const ViewProjection& t, const View& view, double u, double v, double& sx,
             double& sy) {
  const double x = u - t.anchor_x, y = v - t.anchor_y;
  const float* m = t.matrix;
  const double cx = m[0] * x + m[4] * y + m[12], cy = m[1] * x + m[5] * y + m[13];
  const double cw = m[3] * x + m[7] * y + m[15];
  if (!(cw > 0)) return false;
  sx = (cx / cw + 1) / 2 * view.viewportWidth();
  sy = (1 - cy / cw) / 2 * view.viewportHeight();
  return true;
}

TEST(Camera, TheProjectionPutsEachTexelOnThePixelThatSeesIt) {
  ImageInfo info;
  info.width_px = info.height_px = 1 << 20;
  info.tile_size_px = 256;
  info.level_count = levelCountFor(info.width_px, info.height_px, 256);
  std::vector<View> views(3);
  views[0].ortho = {987654.3, 123456.7, 3.3, 160, 120, 0.6};
  views[1].kind = View::Kind::kPerspective;
  views[1].perspective = camera(0.4, -0.55);
  views[2].kind = View::Kind::kPerspective;
  views[2].perspective = camera(-2.0, -1.5);
  for (const View& view : views) {
    const ViewProjection t = viewProjection(view, info);
    for (double sx : {0.5, 40.0, 80.0, 159.5})
      for (double sy : {0.5, 60.0, 119.5}) {
        double u = 0, v = 0;
        if (!textureAt(view, sx, sy, u, v)) continue;
        double px = 0, py = 0;
        ASSERT_TRUE(project(t, view, u, v, px, py));
        // Floats relative to the anchor: well under a hundredth of a pixel.
        EXPECT_NEAR(px, sx, 0.01) << sx << "," << sy;
        EXPECT_NEAR(py, sy, 0.01) << sx << "," << sy;
      }
  }
}

}  // namespace
}  // namespace tessera
