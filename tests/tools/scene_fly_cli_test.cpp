// `tessera fly` and `tessera view` on a scene archive, as real processes: a keyframe flight
// through a small synthetic city at 160x120 on llvmpipe reports no untextured frame and a
// picture at rest that matches every texture resident; a bad path file is named with its line;
// the window (under xvfb-run where installed) writes its screenshot.
#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "support/sanitizers.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;

std::string slurp(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

/// Runs a shell command line (arguments quoted by the caller), with a time limit so a hang
/// fails the test; returns the exit status.
int shell(const std::string& command) {
  const int status = std::system(("timeout --signal=KILL 120 " + command).c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

class SceneCli : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           fmt::format("tessera-scene-cli-{}-{}", ::getpid(),
                       ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    city_ = (dir_ / "city.tess").string();
    ASSERT_EQ(shell(fmt::format("'{}' build synthetic-scene:60:8:2 -o '{}' --tile 64 -q",
                                TESSERA_CLI_PATH, city_)),
              0);
  }
  void TearDown() override { fs::remove_all(dir_); }

  fs::path dir_;
  std::string city_;
};

TEST_F(SceneCli, FlyFollowsAKeyframePathWithNoUntexturedFrame) {
  // The synthetic city spans about 200 m around the origin's quadrant: look at it from a
  // corner, move, stand still (a stop), then teleport.
  const fs::path path = dir_ / "walk.path";
  std::ofstream(path) << "# t x y z look tx ty tz\n"
                         "0 -20 40 -20 look 100 0 100\n"
                         "1 10 30 -10 look 100 0 100\n"
                         "1.5 10 30 -10 look 100 0 100\n"
                         "1.5 60 20 60 90 -30 jump\n"
                         "2 60 20 60 90 -30\n";
  const fs::path out = dir_ / "out";
  ASSERT_EQ(shell(fmt::format("'{}' fly '{}' --path '{}' --viewport 160x120 --fps 10 -o '{}' "
                              "--report --screenshots 3 -q",
                              TESSERA_CLI_PATH, city_, path.string(), out.string())),
            0)
      << slurp(out / "summary.json");
  const nlohmann::json summary = nlohmann::json::parse(slurp(out / "summary.json"));
  EXPECT_EQ(summary["frames"].get<int>(), 21);
  EXPECT_EQ(summary["renderer"], "scene");
  EXPECT_EQ(summary["untextured_frames"].get<int>(), 0);
  EXPECT_GE(summary["first_picture_frame"].get<int>(), 0);
  EXPECT_GE(summary["scene_rest_psnr_db"].get<double>(), 40.0);
  EXPECT_GT(summary["rest"]["objects_drawn"].get<int>(), 0);
  EXPECT_EQ(summary["stops"].size(), 2u);  // 1 to 1.5 s, and 1.5 to 2 s after the jump
  EXPECT_GT(summary["reads"].get<int>(), 0);
  for (const char* file : {"frames.csv", "rest.png", "reference.png", "frame-3.png", "report.html"})
    EXPECT_TRUE(fs::exists(out / file)) << file;
}

TEST_F(SceneCli, FlyNamesABadPathFileAndItsLine) {
  const fs::path path = dir_ / "bad.path";
  std::ofstream(path) << "0 0 10 0 0 -90\n1 0 10 0 look 5\n";
  const fs::path err = dir_ / "err.txt";
  EXPECT_EQ(shell(fmt::format("'{}' fly '{}' --path '{}' --viewport 160x120 -o '{}' 2> '{}'",
                              TESSERA_CLI_PATH, city_, path.string(), (dir_ / "out").string(),
                              err.string())),
            2);
  EXPECT_NE(slurp(err).find(path.string() + ":2:"), std::string::npos) << slurp(err);
  EXPECT_EQ(shell(fmt::format("'{}' fly '{}' --path zoom -o '{}' 2> '{}'", TESSERA_CLI_PATH, city_,
                              (dir_ / "out").string(), err.string())),
            2);
  EXPECT_NE(slurp(err).find("orbit"), std::string::npos) << slurp(err);
}

TEST_F(SceneCli, ViewUnderXvfbWritesAScreenshotWithOverlays) {
  if (shell("sh -c 'command -v xvfb-run' > /dev/null") != 0)
    GTEST_SKIP() << "xvfb-run is not installed";
  ASSERT_EQ(shell(fmt::format(
                "xvfb-run -a -s '-screen 0 640x480x24' env '{}' '{}' view '{}' --size "
                "160x120 --frames 10 --overlays levels,nodes --screenshot-dir '{}' "
                "2> /dev/null",
                test::asanOptionsWithoutLeakCheck(), TESSERA_CLI_PATH, city_, dir_.string())),
            0);
  const std::string png = slurp(dir_ / "tessera-screenshot-1.png");
  ASSERT_GT(png.size(), 8u);
  EXPECT_EQ(png.substr(1, 3), "PNG");
}

}  // namespace
}  // namespace tessera
