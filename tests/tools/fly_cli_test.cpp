// `tessera fly` as a real process, on what must not pass for success: tiles that fail to load
// (corrupt payloads, a server answering 503) end in exit code 4 with the failure named, and
// numbers that are not numbers are refused before the flight.
#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <tessera/archive.h>

#include "support/range_server.h"
#include "support/test_images.h"

extern char** environ;

namespace tessera {
namespace {

/// `tessera fly`'s documented exit code for a flight whose tiles failed to load (cli.h).
constexpr int kExitLoadFailures = 4;

struct RunResult {
  int exit_code = -1;
  std::string out;
  std::string err;
};

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

/// Runs `tessera ARGS` under `timeout`, so a flight that never ends fails the test instead of
/// hanging it; stdout and stderr through files beside `log`.
RunResult runTessera(const std::vector<std::string>& args, const std::string& log) {
  const std::string out_path = log + ".stdout", err_path = log + ".stderr";
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC,
                                   0644);
  posix_spawn_file_actions_addopen(&actions, 2, err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC,
                                   0644);
  std::vector<std::string> argv_strings = {"timeout", "--signal=KILL", "120", TESSERA_CLI_PATH};
  argv_strings.insert(argv_strings.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& arg : argv_strings) argv.push_back(arg.data());
  argv.push_back(nullptr);
  RunResult result;
  pid_t pid = 0;
  const int spawned = posix_spawnp(&pid, "timeout", &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  EXPECT_EQ(spawned, 0) << "cannot run timeout";
  if (spawned != 0) return result;
  int status = 0;
  waitpid(pid, &status, 0);
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  result.out = slurp(out_path);
  result.err = slurp(err_path);
  return result;
}

class FlyCli : public testing::Test {
 protected:
  void SetUp() override {
    dir_ = test::testTempDir();
    std::filesystem::create_directories(dir_);
    archive_ = dir_ + "fly.tess";
    ASSERT_EQ(
        run({"build", "synthetic:4096x2048:2:3", "-o", archive_, "--tile", "128", "-q"}).exit_code,
        0);
  }
  RunResult run(const std::vector<std::string>& args) { return runTessera(args, dir_ + "run"); }
  /// A short flight over `archive` at a small viewport.
  RunResult fly(const std::string& archive, const std::string& out,
                std::vector<std::string> extra = {}) {
    std::vector<std::string> args = {"fly",        archive,   "--fps", "30",
                                     "--viewport", "320x240", "--out", out};
    args.insert(args.end(), extra.begin(), extra.end());
    return run(args);
  }
  std::string dir_, archive_;
};

TEST_F(FlyCli, RefusesNumbersThatAreNotNumbersOrOutOfRange) {
  // --speed nan made the pan's keyframe loop endless; --duration nan or -1 flew one frame and
  // reported success.
  const std::vector<std::vector<std::string>> bad = {
      {"--path", "pan", "--speed", "nan"},
      {"--speed", "-1"},
      {"--speed", "inf"},
      {"--speed", "0"},
      {"--duration", "nan"},
      {"--duration", "-1"},
      {"--duration", "0"},
      {"--duration", "1e9"},
      {"--fps", "nan"},
      {"--still-after", "nan"},
      {"--still-after", "-1"},
      {"--upload-budget", "0"},
      {"--threads", "100000"},
      {"--loader-priority", "realtime"},
      {"--egress", "0.5"},
      {"--egress", "cheap"},
      {"--transcode", "bc7"},
      {"--window", "0,100"},  // without --render there is no picture to window
      {"--gamma", "2"},
  };
  for (const std::vector<std::string>& options : bad) {
    std::string joined;
    for (const std::string& option : options) joined += option + " ";
    SCOPED_TRACE(joined);
    RunResult result = fly(archive_, dir_ + "bad", options);
    EXPECT_EQ(result.exit_code, 2) << result.err;
    EXPECT_NE(result.err.find(options[options.size() - 2]), std::string::npos) << result.err;
  }
  // Keyframe files: a time that is not a number, a line that is not a keyframe, junk after
  // the last field, a negative time.
  const std::vector<std::string> bad_lines = {"nan 600 600 1", "abc 600 600 1",
                                              "0 600 600 1 0 jump x", "0 600 600 1 0 leap",
                                              "-1 600 600 1"};
  for (const std::string& line : bad_lines) {
    SCOPED_TRACE(line);
    const std::string path = dir_ + "bad.path";
    std::ofstream(path) << "# comment\n\n" << line << "\n1 700 700 1\n";
    RunResult result = fly(archive_, dir_ + "bad", {"--path", path});
    EXPECT_EQ(result.exit_code, 2) << result.err;
    EXPECT_NE(result.err.find("bad.path:3"), std::string::npos) << result.err;
  }
}

// --transcode bc1 without a renderer: the loaders encode the JPEG tiles they load and
// summary.json says so, with their time; without the option nothing is transcoded.
TEST_F(FlyCli, TranscodeBc1ReportsTheTranscodedTilesAndTheirTime) {
  const std::string jpeg = dir_ + "jpeg.tess";
  ASSERT_EQ(
      run({"build", "synthetic:512x384:2:3", "-o", jpeg, "--tile", "128", "--codec", "jpeg", "-q"})
          .exit_code,
      0);
  for (const std::string transcode : {"bc1", "none"}) {
    SCOPED_TRACE(transcode);
    const std::string out = dir_ + "transcode-" + transcode;
    RunResult result = fly(jpeg, out, {"--duration", "0.3", "--transcode", transcode, "-q"});
    ASSERT_EQ(result.exit_code, 0) << result.err;
    nlohmann::json summary = nlohmann::json::parse(slurp(out + "/summary.json"));
    const nlohmann::json& t = summary["transcode"];
    EXPECT_EQ(t["requested"], transcode);
    EXPECT_EQ(t["active"].get<bool>(), transcode == "bc1");
    const uint64_t tiles = t["tiles"].get<uint64_t>();
    const double ms = t["ms_total"].get<double>();
    EXPECT_EQ(tiles > 0, transcode == "bc1");
    EXPECT_EQ(ms > 0, transcode == "bc1");
    EXPECT_LE(ms, summary["decode_ms_total"].get<double>());
    EXPECT_LE(tiles, summary["tiles_loaded"].get<uint64_t>());
  }
}

TEST_F(FlyCli, ExitsFourNamingTheTileWhenTilesFailToLoad) {
  // Every level-0 payload under the start of the pan gets a flipped byte: their checksums fail.
  auto archive = Archive::openFile(archive_);
  ASSERT_TRUE(archive) << archive.error().message;
  std::vector<uint8_t> bytes(std::filesystem::file_size(archive_));
  std::ifstream(archive_, std::ios::binary)
      .read(reinterpret_cast<char*>(bytes.data()), std::streamsize(bytes.size()));
  size_t corrupted = 0;
  for (uint32_t y = 6; y < 10; ++y)
    for (uint32_t x = 0; x < 6; ++x) {
      auto entry = (*archive)->tileEntry({0, 0, x, y});
      if (!entry || entry->kind != TileKind::kEncoded) continue;
      bytes[entry->offset_bytes + entry->length_bytes / 2] ^= 0x5a;
      ++corrupted;
    }
  ASSERT_GT(corrupted, 0u);
  const std::string bad = dir_ + "bad.tess";
  std::ofstream(bad, std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));

  RunResult result = fly(bad, dir_ + "bad-out", {"--path", "pan", "--duration", "0.5"});
  EXPECT_EQ(result.exit_code, kExitLoadFailures) << result.err;
  EXPECT_NE(result.err.find("tiles failed to load"), std::string::npos) << result.err;
  EXPECT_NE(result.err.find("checksum"), std::string::npos) << result.err;
  EXPECT_NE(result.err.find("tile (0,"), std::string::npos) << result.err;
  EXPECT_NE(result.out.find("FAILED"), std::string::npos) << result.out;
  // The outputs are written all the same, with the failures in them.
  nlohmann::json summary = nlohmann::json::parse(slurp(dir_ + "bad-out/summary.json"));
  EXPECT_GT(summary["load_failures"].get<uint64_t>(), 0u);
  EXPECT_GT(summary["failed_tiles"].get<uint64_t>(), 0u);
  ASSERT_FALSE(summary["failures"].empty());
  EXPECT_EQ(summary["failures"][0]["level"], 0);
  EXPECT_EQ(summary["failures"][0]["code"], "corrupt");
  EXPECT_NE(summary["failures"][0]["message"].get<std::string>().find("checksum"),
            std::string::npos);

  // The clean archive flies the same path with exit 0.
  RunResult clean = fly(archive_, dir_ + "clean-out", {"--path", "pan", "--duration", "0.5"});
  EXPECT_EQ(clean.exit_code, 0) << clean.err;
  EXPECT_EQ(clean.out.find("FAILED"), std::string::npos) << clean.out;

  // --help lists the code with the others.
  RunResult help = run({"--help"});
  EXPECT_EQ(help.exit_code, 0);
  EXPECT_NE(help.out.find("4 fly or demo: tiles failed to load"), std::string::npos) << help.out;
}

TEST_F(FlyCli, EveryArchiveWithAFailedTileExitsNonZero) {
  // Random bytes flipped anywhere past the header: whatever they hit (payloads, directory
  // pages), a flight that saw a tile fail exits 4, one that saw none exits 0, and one that
  // could not open the archive exits 1. The zoom path shows every level.
  std::vector<uint8_t> clean(std::filesystem::file_size(archive_));
  std::ifstream(archive_, std::ios::binary)
      .read(reinterpret_cast<char*>(clean.data()), std::streamsize(clean.size()));
  std::mt19937_64 random(31);
  int failed_flights = 0, clean_flights = 0;
  for (int trial = 0; trial < 12; ++trial) {
    SCOPED_TRACE(trial);
    std::vector<uint8_t> bytes = clean;
    for (int flip = 0; flip < 4; ++flip)
      bytes[4096 + random() % (bytes.size() - 4096)] ^= uint8_t(1 + random() % 255);
    const std::string path = dir_ + "random.tess", out = dir_ + "random-out";
    std::ofstream(path, std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    std::filesystem::remove_all(out);
    RunResult result = fly(path, out, {"--path", "zoom", "--duration", "0.6", "-q"});
    if (result.exit_code == 1) continue;  // the archive does not open: named on stderr
    ASSERT_TRUE(std::filesystem::exists(out + "/summary.json")) << result.err;
    nlohmann::json summary = nlohmann::json::parse(slurp(out + "/summary.json"));
    const uint64_t failures = summary["load_failures"].get<uint64_t>();
    EXPECT_EQ(result.exit_code, failures > 0 ? kExitLoadFailures : 0)
        << failures << " failures; " << result.err;
    (failures > 0 ? failed_flights : clean_flights) += 1;
  }
  EXPECT_GT(failed_flights, 0) << "no flight hit a corrupt tile: the test tests nothing";
}

TEST_F(FlyCli, AServerAnswering503IsNamedWithItsStatusAndReason) {
  std::vector<uint8_t> bytes(std::filesystem::file_size(archive_));
  std::ifstream(archive_, std::ios::binary)
      .read(reinterpret_cast<char*>(bytes.data()), std::streamsize(bytes.size()));
  test::RangeServer server(bytes, "\"v1\"");
  // The open's request is served; every request after it (directory pages, tiles) is a 503.
  server.setPlan([](uint64_t n) {
    return n == 0 ? test::RangeReply{} : test::RangeReply{test::RangeReply::Kind::kStatus, 503, ""};
  });
  RunResult result = fly(server.url(), dir_ + "http-out", {"--duration", "1"});
  EXPECT_EQ(result.exit_code, kExitLoadFailures) << result.err;
  EXPECT_NE(result.err.find("HTTP 503 Planned"), std::string::npos) << result.err;
  EXPECT_NE(result.err.find(server.url()), std::string::npos) << result.err;
  EXPECT_NE(result.err.find("tile ("), std::string::npos) << result.err;
}

}  // namespace
}  // namespace tessera
