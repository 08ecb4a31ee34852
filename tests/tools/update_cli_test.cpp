// `tessera update`, `append`, `compact` and `info` on an updated archive, through the real
// binary: exit codes and messages (docs/cli.md, "update, append, compact").
#include <filesystem>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "run_program.h"
#include "support/test_images.h"

namespace tessera {
namespace {

using test::RunResult;
using test::runTessera;

TEST(UpdateCli, UpdateAppendCompactAndTheirErrors) {
  const std::string dir = test::testTempDir();
  const std::string logs = dir + "run", archive = dir + "a.tess", patch = dir + "p.png";
  auto run = [&](const std::vector<std::string>& args) { return runTessera(args, logs); };
  ASSERT_EQ(run({"build", "synthetic:300x200:4:3", "-o", archive, "--tile", "64", "--codec", "zstd",
                 "--quiet"})
                .exit_code,
            0);
  test::PngSpec spec;
  spec.width_px = 40;
  spec.height_px = 30;
  test::writePng(patch, spec, test::makeTestPixels(40, 30, 3, 2));

  RunResult updated = run({"update", archive, patch, "--at", "100,50", "--json"});
  ASSERT_EQ(updated.exit_code, 0) << updated.err;
  const nlohmann::json report = nlohmann::json::parse(updated.out, nullptr, false);
  EXPECT_EQ(report.value("version", 0), 2);
  EXPECT_EQ(report.value("file_bytes", uint64_t(0)), std::filesystem::file_size(archive));

  RunResult bad_at = run({"update", archive, patch, "--at", "100;50"});
  EXPECT_EQ(bad_at.exit_code, 2);
  EXPECT_NE(bad_at.err.find("expected X,Y"), std::string::npos) << bad_at.err;
  RunResult outside = run({"update", archive, patch, "--at", "290,10"});
  EXPECT_EQ(outside.exit_code, 2);  // a bad value of an argument: a usage error
  EXPECT_NE(outside.err.find("reaches outside image 0"), std::string::npos) << outside.err;
  RunResult no_image = run({"update", archive, patch, "--at", "0,0", "--image", "3"});
  EXPECT_EQ(no_image.exit_code, 2);
  EXPECT_NE(no_image.err.find("no image 3"), std::string::npos) << no_image.err;

  RunResult ptm = run({"append", archive, "synthetic:90x70:1:3", "--codec", "ptm"});
  EXPECT_EQ(ptm.exit_code, 1);
  EXPECT_NE(ptm.err.find("depend on their parents"), std::string::npos) << ptm.err;
  ASSERT_EQ(run({"append", archive, "synthetic:90x70:1:3"}).exit_code, 0);
  RunResult info = run({"info", archive, "--json"});
  const nlohmann::json json = nlohmann::json::parse(info.out, nullptr, false);
  EXPECT_EQ(json.value("version", 0), 3);
  EXPECT_GT(json.value("dead_bytes", uint64_t(0)), 0u);
  EXPECT_EQ(json["images"].size(), 2u);
  EXPECT_EQ(run({"verify", archive, "-q"}).exit_code, 0);

  const uint64_t before = std::filesystem::file_size(archive);
  ASSERT_EQ(run({"compact", archive}).exit_code, 0);
  EXPECT_LT(std::filesystem::file_size(archive), before);
  EXPECT_EQ(run({"verify", archive, "-q"}).exit_code, 0);
}

}  // namespace
}  // namespace tessera
