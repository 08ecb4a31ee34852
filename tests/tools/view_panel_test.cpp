// `tessera view`'s panel leaves the picture visible: its box is a function of the window
// (view_panel.h), and on a virtual X server the real panel, as the viewer reports it after
// --frames, covers at most an eighth of a 1280x720 window.
#include "view_panel.h"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>

#include "support/sanitizers.h"
#include "support/test_images.h"

extern char** environ;

namespace tessera::cli {
namespace {

TEST(ViewPanel, TakesAboutAQuarterOfTheWidthAndFitsTheWindow) {
  for (const auto& [w, h] : std::array<std::pair<int, int>, 5>{
           {{1280, 720}, {1920, 1080}, {3840, 2160}, {800, 600}, {320, 240}}}) {
    SCOPED_TRACE(testing::Message() << w << "x" << h);
    const PanelLayout layout = panelLayout(w, h);
    EXPECT_GE(layout.x, 0);
    EXPECT_GE(layout.y, 0);
    EXPECT_LE(layout.x + layout.width, float(w));
    EXPECT_LE(layout.y + layout.max_height, float(h));
    EXPECT_LE(layout.width, std::max(0.3f * float(w), 280.0f));
    EXPECT_LE(layout.width, 360.0f);
  }
  EXPECT_FLOAT_EQ(panelLayout(1280, 720).width, 307.2f);
}

TEST(ViewPanel, GraphsPlotOnlyTheSamplesRecordedOldestFirst) {
  std::array<float, 8> ring{};
  // Three samples so far: the graph shows three, not eight with five zeros.
  ring[0] = 16, ring[1] = 17, ring[2] = 40;
  PlotWindow window = plotWindow(ring.data(), ring.size(), 3, 3, 20);
  EXPECT_EQ(window.count, 3);
  EXPECT_EQ(window.offset, 0);
  EXPECT_EQ(window.largest, 40);
  EXPECT_EQ(window.max, 50);  // a quarter above the largest
  // Full: every sample, from the oldest (where the next write goes).
  for (size_t i = 0; i < ring.size(); ++i) ring[i] = float(i);
  window = plotWindow(ring.data(), ring.size(), 5, 100, 20);
  EXPECT_EQ(window.count, 8);
  EXPECT_EQ(window.offset, 5);
  EXPECT_EQ(window.max, 20);  // at least the smallest scale
  EXPECT_EQ(plotWindow(ring.data(), ring.size(), 0, 0, 20).count, 0);
}

/// The directory on PATH holding `name`, or "".
std::string onPath(const std::string& name) {
  std::stringstream dirs(std::getenv("PATH") ? std::getenv("PATH") : "");
  for (std::string dir; std::getline(dirs, dir, ':');)
    if (::access((dir + "/" + name).c_str(), X_OK) == 0) return dir + "/" + name;
  return "";
}

/// Runs `argv`, returning its exit code and stderr.
std::pair<int, std::string> run(std::vector<std::string> argv, const std::string& log) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
  posix_spawn_file_actions_addopen(&actions, 2, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  std::vector<char*> args;
  for (std::string& arg : argv) args.push_back(arg.data());
  args.push_back(nullptr);
  pid_t pid = 0;
  const int spawned = posix_spawn(&pid, args[0], &actions, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (spawned != 0) return {-1, "cannot run " + argv[0]};
  int status = 0;
  waitpid(pid, &status, 0);
  std::stringstream err;
  err << std::ifstream(log).rdbuf();
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, err.str()};
}

TEST(ViewPanel, CoversAtMostAnEighthOfTheWindowUnderXvfb) {
  const std::string xvfb_run = onPath("xvfb-run");
  if (xvfb_run.empty()) GTEST_SKIP() << "xvfb-run is not installed (apt-get install xvfb)";
  const std::string dir = test::testTempDir();
  const std::string archive = dir + "panel.tess";
  ASSERT_EQ(
      run({TESSERA_CLI_PATH, "build", "synthetic:4096x4096", "-o", archive, "-q"}, dir + "log")
          .first,
      0);
  const auto [code, err] =
      run({xvfb_run, "-a", "-s", "-screen 0 1600x900x24", "env",
           test::asanOptionsWithoutLeakCheck(), TESSERA_CLI_PATH, "view", archive, "--size",
           "1280x720", "--frames", "30", "--screenshot-dir", dir},
          dir + "log");
  ASSERT_EQ(code, 0) << err;
  float x = 0, y = 0, w = 0, h = 0;
  int fw = 0, fh = 0;
  const size_t at = err.find("panel at ");
  ASSERT_NE(at, std::string::npos) << err;
  ASSERT_EQ(
      std::sscanf(err.c_str() + at, "panel at %f,%f, %fx%f of %dx%d", &x, &y, &w, &h, &fw, &fh), 6)
      << err;
  EXPECT_EQ(fw, 1280);
  EXPECT_EQ(fh, 720);
  EXPECT_LE(x + w, float(fw));
  EXPECT_LE(y + h, float(fh));
  EXPECT_LE(w * h, float(fw * fh) / 8) << w << "x" << h << " of " << fw << "x" << fh;
}

}  // namespace
}  // namespace tessera::cli
