// The kill loop (issue 31): `tessera build` killed with SIGKILL at 100 random points of its
// run never leaves at its output a file that `verify` rejects: the path holds either the
// archive that was there before, untouched, or the complete new one. The points are spread
// uniformly over the measured length of one build, so every phase (reading, encoding,
// writing pages, committing) is hit.
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <random>
#include <thread>

#include <gtest/gtest.h>

#include <tessera/archive.h>

#include "support/test_images.h"

extern char** environ;

namespace tessera {
namespace {

pid_t startBuild(const std::string& input, const std::string& output) {
  std::vector<std::string> args = {TESSERA_CLI_PATH, "build", input,    "-o",  output,
                                   "--codec",        "png",   "--tile", "128", "--quiet"};
  std::vector<char*> argv;
  for (std::string& arg : args) argv.push_back(arg.data());
  argv.push_back(nullptr);
  pid_t pid = -1;
  if (posix_spawn(&pid, argv[0], nullptr, nullptr, argv.data(), environ) != 0) return -1;
  return pid;
}

int waitExit(pid_t pid) {
  int status = 0;
  waitpid(pid, &status, 0);
  return status;
}

// The archive at `path`: "" when it verifies, else what is wrong.
std::string verdict(const std::string& path) {
  Result<std::shared_ptr<Archive>> archive = Archive::openFile(path);
  if (!archive) return archive.error().message;
  const VerifyReport report = (*archive)->verify();
  return report.ok() ? "" : report.faults.front();
}

TEST(KillLoop, SigkillAnywhereInABuildLeavesTheOldOrTheNewArchive) {
  const std::string dir = test::testTempDir();
  const std::string output = dir + "out.tess";
  const std::string old_input = "synthetic:300x200:1:3";
  const std::string new_input = "synthetic:1536x1536:2:4";
  // The archive that is there before every killed build.
  ASSERT_EQ(WEXITSTATUS(waitExit(startBuild(old_input, output))), 0);
  const uint64_t old_bytes = std::filesystem::file_size(output);
  // The longest of two builds: on a busy machine (CI runs tests two at a time) one build can
  // be much quicker than the killed ones, and points must reach past their commits too.
  double build_s = 0;
  for (int i = 0; i < 2; ++i) {
    const auto started = std::chrono::steady_clock::now();
    ASSERT_EQ(WEXITSTATUS(waitExit(startBuild(new_input, dir + "new.tess"))), 0);
    build_s = std::max(
        build_s, std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count());
  }
  const uint64_t new_bytes = std::filesystem::file_size(dir + "new.tess");

  std::mt19937 random(27);
  std::uniform_real_distribution<double> point(0.0, build_s * 1.6);
  int old_kept = 0, new_written = 0;
  for (int round = 0; round < 100; ++round) {
    ASSERT_EQ(WEXITSTATUS(waitExit(startBuild(old_input, output))), 0) << "round " << round;
    const pid_t pid = startBuild(new_input, output);
    ASSERT_GT(pid, 0);
    // The kill point: a random instant of the build (waiting is the point, not a sync).
    std::this_thread::sleep_for(std::chrono::duration<double>(point(random)));
    kill(pid, SIGKILL);
    waitExit(pid);
    ASSERT_TRUE(std::filesystem::exists(output)) << "round " << round << ": the output vanished";
    const std::string fault = verdict(output);
    ASSERT_EQ(fault, "") << "round " << round << ": " << output << " does not verify";
    const uint64_t bytes = std::filesystem::file_size(output);
    ASSERT_TRUE(bytes == old_bytes || bytes == new_bytes) << "round " << round;
    (bytes == old_bytes ? old_kept : new_written) += 1;
  }
  // Both outcomes happened, so the points did fall before and after the commit.
  EXPECT_GT(old_kept, 0);
  EXPECT_GT(new_written, 0);
  // No temporary is left beside the output (O_TMPFILE files vanish with the process; named
  // temporaries are only used where the file system lacks O_TMPFILE).
  size_t leftovers = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir))
    if (entry.path().filename().string().find(".tmp-") != std::string::npos) ++leftovers;
  EXPECT_EQ(leftovers, 0u);
}

}  // namespace
}  // namespace tessera
