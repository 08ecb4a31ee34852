// The viewer's camera: zoom keeps the texel under the cursor, drags move the texture with the
// mouse, fit shows the whole image, and switching between the 2D view and the fly-over keeps
// the place and the scale.
#include "tools/view_camera.h"

#include <cmath>

#include <gtest/gtest.h>

namespace tessera::cli {
namespace {

ImageInfo image(uint32_t w, uint32_t h) {
  ImageInfo info;
  info.width_px = w;
  info.height_px = h;
  info.channels = 3;
  info.tile_size_px = 256;
  info.level_count = levelCountFor(w, h, 256);
  return info;
}

View orthoView(const OrthoView& o) {
  View v;
  v.ortho = o;
  return v;
}

TEST(ViewCamera, FitShowsTheWholeImageCentred) {
  const ImageInfo info = image(100000, 20000);
  const OrthoView o = fitImage(info, 1000, 500);
  EXPECT_DOUBLE_EQ(o.centre_x, 50000);
  EXPECT_DOUBLE_EQ(o.centre_y, 10000);
  const auto top_left = planeAt(orthoView(o), 0, 0);
  const auto bottom_right = planeAt(orthoView(o), 1000, 500);
  ASSERT_TRUE(top_left && bottom_right);
  EXPECT_LE(top_left->x, 0);
  EXPECT_LE(top_left->y, 0);
  EXPECT_GE(bottom_right->x, 100000);
  EXPECT_GE(bottom_right->y, 20000);
  EXPECT_LT(bottom_right->x - top_left->x, 1.1 * 100000);  // no more than the margin
}

TEST(ViewCamera, ZoomKeepsTheTexelUnderTheCursor) {
  const ImageInfo info = image(50000, 50000);
  OrthoView o = fitImage(info, 800, 600);
  o.rotation_rad = 0.3;  // the inverse holds for rotated views too
  const auto before = planeAt(orthoView(o), 123, 456);
  zoomAround(o, info, 0.5, 123, 456);
  const auto after = planeAt(orthoView(o), 123, 456);
  ASSERT_TRUE(before && after);
  EXPECT_NEAR(before->x, after->x, 1e-6);
  EXPECT_NEAR(before->y, after->y, 1e-6);
}

TEST(ViewCamera, ZoomStopsAtItsLimits) {
  const ImageInfo info = image(4000, 3000);
  OrthoView o = fitImage(info, 800, 600);
  for (int i = 0; i < 200; ++i) zoomAround(o, info, 0.5, 400, 300);
  EXPECT_DOUBLE_EQ(o.texels_per_pixel, minTexelsPerPixel());
  for (int i = 0; i < 200; ++i) zoomAround(o, info, 2, 400, 300);
  EXPECT_DOUBLE_EQ(o.texels_per_pixel, maxTexelsPerPixel(info, 800, 600));
}

TEST(ViewCamera, DragMovesTheTextureWithTheMouse) {
  const ImageInfo info = image(50000, 50000);
  OrthoView o = fitImage(info, 800, 600);
  o.texels_per_pixel = 2;
  const auto grabbed = planeAt(orthoView(o), 100, 100);
  panByScreen(o, 30, -20);
  const auto now = planeAt(orthoView(o), 130, 80);
  ASSERT_TRUE(grabbed && now);
  EXPECT_NEAR(grabbed->x, now->x, 1e-9);
  EXPECT_NEAR(grabbed->y, now->y, 1e-9);
}

TEST(ViewCamera, CentreStaysOnTheImage) {
  const ImageInfo info = image(1000, 800);
  OrthoView o = fitImage(info, 800, 600);
  panByScreen(o, 1e6, -1e6);
  clampToImage(o, info);
  EXPECT_DOUBLE_EQ(o.centre_x, 0);
  EXPECT_DOUBLE_EQ(o.centre_y, 800);
}

TEST(ViewCamera, FlyOverLooksAtTheOrthoCentreAtItsScale) {
  const ImageInfo info = image(100000, 100000);
  OrthoView o;
  o.centre_x = 30000;
  o.centre_y = 40000;
  o.texels_per_pixel = 4;
  o.viewport_w = 1280;
  o.viewport_h = 720;
  const PerspectiveView p = perspectiveFrom(o, info, -0.6);
  View v;
  v.kind = View::Kind::kPerspective;
  v.perspective = p;
  const auto seen = planeAt(v, 640, 360);
  ASSERT_TRUE(seen);
  EXPECT_NEAR(seen->x, 30000, 1);
  EXPECT_NEAR(seen->y, 40000, 1);
  // And back: the same place at about the same scale.
  const OrthoView back = orthoFrom(p, info);
  EXPECT_NEAR(back.centre_x, 30000, 1);
  EXPECT_NEAR(back.centre_y, 40000, 1);
  EXPECT_NEAR(back.texels_per_pixel, 4, 0.01);
}

TEST(ViewCamera, RaysAboveTheHorizonMissThePlane) {
  View v;
  v.kind = View::Kind::kPerspective;
  v.perspective.pitch_rad = -0.1;
  v.perspective.fov_y_rad = 1.0;
  EXPECT_FALSE(planeAt(v, 640, 0));
  EXPECT_TRUE(planeAt(v, 640, 719));
}

TEST(ViewCamera, FlyControlsMoveAlongTheHeadingAndKeepPitchBelowTheHorizon) {
  const ImageInfo info = image(100000, 100000);
  PerspectiveView p;
  p.eye_x = 50000;
  p.eye_y = 50000;
  p.eye_z = 100;
  p.yaw_rad = 0;  // looks towards -y
  flyMove(p, info, 1, 0);
  EXPECT_NEAR(p.eye_x, 50000, 1e-9);
  EXPECT_NEAR(p.eye_y, 49900, 1e-9);
  flyMove(p, info, 0, 1);  // right is +x at yaw 0
  EXPECT_NEAR(p.eye_x, 50100, 1e-9);
  flyTurn(p, 0, -1e6);
  EXPECT_LT(p.pitch_rad, 0);
  flyTurn(p, 0, 1e6);
  EXPECT_GT(p.pitch_rad, -1.5708);
  flyClimb(p, info, 1e-9);
  EXPECT_DOUBLE_EQ(p.eye_z, minAltitude());
  flyClimb(p, info, 1e12);
  EXPECT_DOUBLE_EQ(p.eye_z, maxAltitude(info));
}

}  // namespace
}  // namespace tessera::cli
