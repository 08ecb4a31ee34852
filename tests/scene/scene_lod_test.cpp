// Per-object levels against hand-computed cases, and the frustum test.
#include "scene_lod.h"

#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

namespace tessera::detail {
namespace {

// Looking straight down the z axis from (0, 0, eye_z); tan(fov / 2) = 0.5 over 1000 rows, so
// one pixel spans 0.001 radians (pixelAngle) and a 10-unit box at distance d covers 10 /
// (d * 0.001) pixels.
PerspectiveView downFrom(double eye_z) {
  PerspectiveView camera;
  camera.eye_z = eye_z;
  camera.pitch_rad = -M_PI / 2;
  camera.fov_y_rad = 2 * std::atan(0.5);
  camera.viewport_w = camera.viewport_h = 1000;
  return camera;
}

const Box3 kTenUnits{{-5, -5, 0}, {5, 5, 0}};

ImageInfo texture1024x512() {
  ImageInfo info;
  info.width_px = 1024;
  info.height_px = 512;
  info.channels = 3;
  info.tile_size_px = 64;
  info.level_count = levelCountFor(1024, 512, 64);
  return info;
}

TEST(SceneLod, LevelFollowsTheProjectedTexelDensity) {
  const ImageInfo info = texture1024x512();
  ASSERT_EQ(info.level_count, 5u);  // 1024, 512, 256, 128, 64 wide
  EXPECT_DOUBLE_EQ(pixelAngle(downFrom(100)), 0.001);
  // d = 100: 100 px across, 1024 texels: rho = 10.24, log2 = 3.36 -> level 3.
  ObjectLod lod = objectLod(downFrom(100), kTenUnits, info, 0);
  EXPECT_EQ(lod.level, 3u);
  EXPECT_EQ(lod.pixels, 10000u);
  // d = 10: 1000 px across: rho = 1.024 -> level 0; the whole viewport at most.
  lod = objectLod(downFrom(10), kTenUnits, info, 0);
  EXPECT_EQ(lod.level, 0u);
  EXPECT_EQ(lod.pixels, 1000000u);
  // d = 40: 250 px: rho = 4.096 -> level 2 (log2 = 2.03).
  EXPECT_EQ(objectLod(downFrom(40), kTenUnits, info, 0).level, 2u);
  // d = 10000: 1 px: rho = 1024 -> level 10, clamped to the coarsest (4).
  EXPECT_EQ(objectLod(downFrom(10000), kTenUnits, info, 0).level, 4u);
  // A bias of +1 asks one level coarser.
  EXPECT_EQ(objectLod(downFrom(100), kTenUnits, info, 1).level, 4u);
  // The eye inside the box: the finest level, the whole screen.
  lod = objectLod(downFrom(0), Box3{{-5, -5, -1}, {5, 5, 1}}, info, 0);
  EXPECT_EQ(lod.level, 0u);
  EXPECT_EQ(lod.pixels, 1000000u);
}

TEST(SceneLod, DistanceIsToTheNearestPointOfTheBox) {
  PerspectiveView camera = downFrom(100);
  camera.eye_x = 8;  // 3 units beyond the box's x side, 100 above
  EXPECT_DOUBLE_EQ(distanceToBox(camera, kTenUnits), std::sqrt(9.0 + 10000.0));
}

TEST(SceneLod, FrustumKeepsWhatIsInFrontAndDropsWhatIsBehindOrAside) {
  const Frustum frustum = frustumOf(downFrom(100));
  EXPECT_TRUE(boxMayBeVisible(frustum, kTenUnits));
  // Above the eye (behind a camera looking down).
  EXPECT_FALSE(boxMayBeVisible(frustum, Box3{{-5, -5, 150}, {5, 5, 160}}));
  // At 100 below, the view spans +-50 across (tan 0.5): a box at x 60..70 is outside.
  EXPECT_FALSE(boxMayBeVisible(frustum, Box3{{60, -5, 0}, {70, 5, 0}}));
  EXPECT_TRUE(boxMayBeVisible(frustum, Box3{{45, -5, 0}, {70, 5, 0}}));
  EXPECT_FALSE(boxMayBeVisible(frustum, Box3{{-5, -70, 0}, {5, -60, 0}}));
  // Wholly inside: the central box; not the one straddling the edge at x = 50.
  EXPECT_TRUE(boxInside(frustum, kTenUnits));
  EXPECT_FALSE(boxInside(frustum, Box3{{45, -5, 0}, {70, 5, 0}}));
  EXPECT_FALSE(boxInside(frustum, Box3{{-5, -5, 50}, {5, 5, 150}})) << "reaches behind the eye";
}

TEST(SceneLod, PerObjectScaleGivesTheSameLevelsAsObjectLod) {
  const ImageInfo info = texture1024x512();
  for (double eye_z : {0.0, 5.0, 10.0, 40.0, 100.0, 333.0, 10000.0}) {
    for (double bias : {-1.0, 0.0, 0.5, 2.0}) {
      const LodFrame frame = lodFrame(downFrom(eye_z), bias);
      const ObjectScale scale = objectScale(frame, kTenUnits);
      const ObjectLod lod = objectLod(downFrom(eye_z), kTenUnits, info, bias);
      EXPECT_EQ(levelFor(frame, scale, info), lod.level) << eye_z << " " << bias;
      EXPECT_EQ(scale.pixels, lod.pixels);
      // floor(log2(rho) + bias) by hand where the eye is outside the box.
      if (eye_z > 0) {
        const double rho = 1024 / (10 / (eye_z * 0.001));
        const double expected = std::clamp(std::floor(std::log2(rho) + bias), 0.0, 4.0);
        EXPECT_EQ(lod.level, uint32_t(expected)) << eye_z << " " << bias;
      }
    }
  }
}

}  // namespace
}  // namespace tessera::detail
