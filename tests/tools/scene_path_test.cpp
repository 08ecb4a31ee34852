// Scene camera paths: the pose's PerspectiveView looks where the pose does with the world's up
// on the screen's up, keyframes interpolate and stop, and bad files are named by line.
#include "scene_path.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>

#include <gtest/gtest.h>

namespace tessera::cli {
namespace {

constexpr double kPi = std::numbers::pi;

double dot(const Vec3& a, const Vec3& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}

TEST(ScenePath, PerspectiveLooksAlongThePoseWithTheWorldUpOnTop) {
  for (double yaw : {0.0, 0.7, -2.0, kPi})
    for (double pitch : {0.0, -0.4, 0.3, -1.5}) {
      const ScenePose pose{1, 2, 3, yaw, pitch};
      const CameraBasis b = cameraBasis(perspectiveOf(pose, 1.0, 160, 120));
      const Vec3 expected{std::sin(yaw) * std::cos(pitch), std::sin(pitch),
                          -std::cos(yaw) * std::cos(pitch)};
      EXPECT_NEAR(dot(b.forward, expected), 1, 1e-9) << yaw << " " << pitch;
      // The screen's right (-basis.right for the scene renderer) stays level, and the
      // screen's up climbs: the picture is upright.
      EXPECT_NEAR(b.right.y, 0, 1e-9) << yaw << " " << pitch;
      EXPECT_GT(b.up.y, 0) << yaw << " " << pitch;
      // Looking north (yaw 0), the screen's right is east (+x).
      if (yaw == 0) {
        EXPECT_NEAR(-b.right.x, 1, 1e-9);
      }
    }
}

TEST(ScenePath, LookAtPointsAtTheTarget) {
  const ScenePose pose = lookAt(0, 10, 0, 10, 0, -10);
  EXPECT_NEAR(pose.yaw_rad, kPi / 4, 1e-12);
  EXPECT_NEAR(pose.pitch_rad, -std::atan2(10, std::hypot(10, 10)), 1e-12);
}

TEST(ScenePath, InterpolatesTurnsTheShortWayAndFindsStops) {
  ScenePath path;
  path.keys = {{0, {0, 0, 0, 3.0, 0}, false},
               {2, {10, 0, 0, -3.0, 0}, false},
               {4, {10, 0, 0, -3.0, 0}, false},
               {4, {50, 0, 0, 0, 0}, true},
               {6, {50, 0, 0, 0, 0}, false}};
  const ScenePose middle = path.at(1);
  EXPECT_NEAR(middle.x, 5, 1e-12);
  // From 3 to -3 rad the short way passes pi, not 0.
  EXPECT_NEAR(std::cos(middle.yaw_rad), std::cos(kPi), 1e-3);
  EXPECT_EQ(path.at(5).x, 50);
  const std::vector<SceneStop> stops = path.stops();
  ASSERT_EQ(stops.size(), 2u);
  EXPECT_EQ(stops[0].from_s, 2);
  EXPECT_EQ(stops[0].until_s, 4);
  EXPECT_EQ(stops[1].from_s, 4);
}

TEST(ScenePath, FilesParseBothFormsAndNameBadLines) {
  const std::filesystem::path file =
      std::filesystem::temp_directory_path() / "tessera-scene-path-test.path";
  std::ofstream(file) << "# comment\n0 1 2 3 90 -45\n1 1 2 3 look 1 0 3 jump\n";
  Result<ScenePath> path = loadScenePathFile(file.string());
  ASSERT_TRUE(path.has_value()) << path.error().message;
  ASSERT_EQ(path->keys.size(), 2u);
  EXPECT_NEAR(path->keys[0].pose.yaw_rad, kPi / 2, 1e-12);
  EXPECT_NEAR(path->keys[1].pose.pitch_rad, -kPi / 2, 1e-12);
  EXPECT_TRUE(path->keys[1].jump);
  for (const char* bad : {"0 1 2 3 90\n", "0 1 2 3 90 100\n", "0 1 2 nan 0 0\n",
                          "1 0 0 0 0 0\n0 0 0 0 0 0\n", "0 1 2 3 look 1 2\n"}) {
    std::ofstream(file) << "# first\n" << bad;
    Result<ScenePath> refused = loadScenePathFile(file.string());
    ASSERT_FALSE(refused.has_value()) << bad;
    EXPECT_NE(refused.error().message.find(file.string() + ":"), std::string::npos)
        << refused.error().message;
  }
  std::filesystem::remove(file);
}

// The view cell is the hints' grid cell under the eye, spanning the scene's height.
TEST(ScenePath, ViewCellBoxIsTheGridCellUnderTheEye) {
  CoverageHints hints;
  hints.up_axis = 1;  // y up: cells on x (u) and z (v)
  hints.cells_u = 4;
  hints.cells_v = 3;
  hints.origin_u = -100;
  hints.origin_v = 50;
  hints.cell_size = 25;
  const Box3 bounds{{-100, -5, 50}, {0, 40, 125}};
  PerspectiveView camera;
  camera.eye_x = -40;  // u cell 2
  camera.eye_y = 10;
  camera.eye_z = 80;  // v cell 1
  const std::optional<Box3> cell = viewCellBox(hints, camera, bounds);
  ASSERT_TRUE(cell);
  EXPECT_EQ(*cell, (Box3{{-50, -5, 75}, {-25, 40, 100}}));
  camera.eye_x = 1000;  // far outside the grid
  EXPECT_FALSE(viewCellBox(hints, camera, bounds));
  camera.eye_x = -110;  // within one cell of the grid: clamped to its edge cell
  ASSERT_TRUE(viewCellBox(hints, camera, bounds));
  EXPECT_EQ(viewCellBox(hints, camera, bounds)->min[0], -100.f);
}

}  // namespace
}  // namespace tessera::cli
