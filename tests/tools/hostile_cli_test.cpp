// The `tessera` command against hostile files and hostile command lines, run as a real process
// with its peak memory measured (issue 31): headers claiming absurd sizes fail with one line
// within the stated budget and never abort; special files at the output are refused and kept;
// bad numbers and misspelt names are usage errors that say what is accepted; extract crops
// edge tiles; free-form metadata never throws; SIGTERM exits 143.
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include <gtest/gtest.h>

#include "support/archive_fixture.h"
#include "support/sanitizers.h"
#include "support/test_images.h"

extern char** environ;

namespace tessera {
namespace {

struct Outcome {
  bool exited = false;        ///< ended by exit, not by a signal (an abort is SIGABRT)
  int exit_code = -1;         ///< when exited
  int signal = 0;             ///< the signal that ended it otherwise
  uint64_t peak_rss_kib = 0;  ///< ru_maxrss of the child
  std::string out, err;
};

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

/// Runs the tessera binary with `args`; with `signal_after`, sends `signal_number` after that
/// long. Captures stdout, stderr, how it ended and its peak resident set.
Outcome runTessera(const std::vector<std::string>& args, const std::string& logs,
                   std::chrono::milliseconds signal_after = {}, int signal_number = 0) {
  const std::string out_path = logs + ".stdout", err_path = logs + ".stderr";
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC,
                                   0644);
  posix_spawn_file_actions_addopen(&actions, 2, err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC,
                                   0644);
  std::vector<std::string> strings = {TESSERA_CLI_PATH};
  strings.insert(strings.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& arg : strings) argv.push_back(arg.data());
  argv.push_back(nullptr);
  Outcome run;
  pid_t pid = 0;
  const int spawned = posix_spawn(&pid, TESSERA_CLI_PATH, &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  EXPECT_EQ(spawned, 0) << "cannot run " << TESSERA_CLI_PATH;
  if (spawned != 0) return run;
  if (signal_number != 0) {
    std::this_thread::sleep_for(signal_after);
    ::kill(pid, signal_number);
  }
  int status = 0;
  rusage usage{};
  ::wait4(pid, &status, 0, &usage);
  run.exited = WIFEXITED(status);
  run.exit_code = run.exited ? WEXITSTATUS(status) : -1;
  run.signal = WIFSIGNALED(status) ? WTERMSIG(status) : 0;
  run.peak_rss_kib = uint64_t(usage.ru_maxrss);
  run.out = slurp(out_path);
  run.err = slurp(err_path);
  std::filesystem::remove(out_path);
  std::filesystem::remove(err_path);
  return run;
}

/// A PNG signature, an IHDR of any size and colour type (CRC included), an empty IDAT and IEND:
/// 57 bytes that claim whatever they like.
std::vector<uint8_t> pngHeader(uint32_t width, uint32_t height, uint8_t colour_type) {
  std::vector<uint8_t> out = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  auto u32 = [&](uint32_t v) {
    for (int shift = 24; shift >= 0; shift -= 8) out.push_back(uint8_t(v >> shift));
  };
  auto chunk = [&](const char* type, const std::vector<uint8_t>& data) {
    u32(uint32_t(data.size()));
    const size_t start = out.size();
    out.insert(out.end(), type, type + 4);
    out.insert(out.end(), data.begin(), data.end());
    uint32_t crc = 0xffffffffu;  // CRC-32 (ISO 3309), bit by bit
    for (size_t i = start; i < out.size(); ++i) {
      crc ^= out[i];
      for (int bit = 0; bit < 8; ++bit) crc = (crc >> 1) ^ (0xedb88320u & (0u - (crc & 1)));
    }
    u32(~crc);
  };
  std::vector<uint8_t> ihdr;
  for (uint32_t v : {width, height})
    for (int shift = 24; shift >= 0; shift -= 8) ihdr.push_back(uint8_t(v >> shift));
  ihdr.insert(ihdr.end(), {8, colour_type, 0, 0, 0});
  chunk("IHDR", ihdr);
  chunk("IDAT", {});
  chunk("IEND", {});
  return out;
}

/// A JPEG whose frame header claims 65500 x 65500 px over the data of a 16 x 16 image.
std::vector<uint8_t> jpegClaiming65500(const std::string& dir) {
  const std::string path = dir + "small.jpg";
  EXPECT_EQ(test::writeJpeg(path, {16, 16, 3, 90, false}, test::makeTestPixels(16, 16, 3)), "");
  std::vector<uint8_t> bytes = test::readFileBytes(path);
  std::filesystem::remove(path);
  for (size_t i = 0; i + 8 < bytes.size(); ++i) {
    if (bytes[i] == 0xff && bytes[i + 1] == 0xc0) {  // SOF0: length, precision, height, width
      bytes[i + 5] = bytes[i + 7] = 0xff;
      bytes[i + 6] = bytes[i + 8] = 0xdc;
      return bytes;
    }
  }
  ADD_FAILURE() << "no SOF0 in " << path;
  return bytes;
}

mode_t fileType(const std::string& path) {
  struct stat st {};
  return ::lstat(path.c_str(), &st) == 0 ? st.st_mode & S_IFMT : 0;
}

size_t lineCount(const std::string& text) {
  return size_t(std::count(text.begin(), text.end(), '\n'));
}

class HostileCli : public testing::Test {
 protected:
  void SetUp() override {
    dir_ = test::testTempDir();
    logs_ = dir_ + "run";
  }
  Outcome run(const std::vector<std::string>& args) { return runTessera(args, logs_); }
  /// A small archive of 300 x 200 px in 64-px tiles with a 2-texel border.
  std::string smallArchive() {
    const std::string path = dir_ + "small.tess";
    Outcome built = run({"build", "synthetic:300x200:3:4", "-o", path, "--tile", "64", "--border",
                         "2", "--codec", "png", "-q"});
    EXPECT_EQ(built.exit_code, 0) << built.err;
    return path;
  }
  std::string dir_, logs_;
};

// ---- Memory bounded by what a file claims --------------------------------------------------

TEST_F(HostileCli, HeadersClaimingAbsurdSizesFailInOneLineWithinTheBudget) {
  struct Case {
    std::string name;
    std::vector<uint8_t> bytes;
  };
  const std::vector<Case> cases = {
      {"rgba-16777216.png", pngHeader(16777216, 16777216, 6)},
      {"rgba-2000000.png", pngHeader(2000000, 2000000, 6)},
      {"rgba-1000000.png", pngHeader(1000000, 1000000, 6)},
      {"gray-16777216.tif", test::makeRawTiffHeader(16777216, 16777216, 16)},
      {"gray-2000000.tif", test::makeRawTiffHeader(2000000, 2000000, 16)},
      {"rgb-65500.jpg", jpegClaiming65500(dir_)},
  };
  constexpr uint64_t kBudgetMiB = 128;
  for (const Case& c : cases) {
    ASSERT_TRUE(test::writeFileBytes(dir_ + c.name, c.bytes));
    for (const char* limit : {"", "128M"}) {
      std::vector<std::string> args = {"build", dir_ + c.name, "-o", dir_ + "out.tess", "-q"};
      if (*limit) args.insert(args.end(), {"--memory-limit", limit});
      const auto started = std::chrono::steady_clock::now();
      Outcome result = run(args);
      const double seconds =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
      ASSERT_TRUE(result.exited) << c.name << ": killed by signal " << result.signal;
      EXPECT_EQ(result.exit_code, 1) << c.name << " " << limit << ": " << result.err;
      EXPECT_EQ(lineCount(result.err), 1u) << result.err;
      EXPECT_EQ(result.err.rfind("tessera: " + dir_, 0), 0u) << result.err;
      EXPECT_LT(seconds, 10) << c.name << " " << limit;
      // Under the default limit (half of this machine's memory) a file may pass the memory
      // check and fail on free space or at its first row; either way nothing is allocated.
      // The ASan and UBSan runtimes hold far more than the program: peak memory is compared in
      // plain builds only.
      if (!test::sanitized()) {
        EXPECT_LT(result.peak_rss_kib, kBudgetMiB * 1024) << c.name;
      }
      if (*limit) {
        EXPECT_EQ(result.err.rfind("tessera: " + dir_ + c.name + ": claims ", 0), 0u) << result.err;
        EXPECT_NE(result.err.find("over the 128.0 MiB limit (--memory-limit)"), std::string::npos)
            << result.err;
      }
      EXPECT_FALSE(std::filesystem::exists(dir_ + "out.tess"));
    }
  }
}

TEST_F(HostileCli, AHeaderWithinTheBudgetFailsAtItsFirstRowWithoutGrowing) {
  // 200000 x 200000 gray: about 220 MiB of bands and tile entries before this change wrote them
  // all; now they are reserved and only the rows that arrive (none) cost memory.
  ASSERT_TRUE(test::writeFileBytes(dir_ + "gray.png", pngHeader(200000, 200000, 0)));
  Outcome result = run({"build", dir_ + "gray.png", "-o", dir_ + "out.tess", "-q", "--threads", "2",
                        "--memory-limit", "2G"});
  ASSERT_TRUE(result.exited) << "killed by signal " << result.signal;
  if (result.err.find(" free in ") != std::string::npos)
    GTEST_SKIP() << "the build needs about 2 GiB free in the temporary directory: " << result.err;
  EXPECT_EQ(result.exit_code, 1) << result.err;
  EXPECT_NE(result.err.find("gray.png: row 0: truncated or corrupt data"), std::string::npos)
      << result.err;
  if (!test::sanitized()) {  // peak memory: plain builds only
    EXPECT_LT(result.peak_rss_kib, 100u * 1024) << result.err;
  }
}

TEST_F(HostileCli, AHundredThousandThreadsIsAUsageErrorNotAnAbort) {
  Outcome result =
      run({"build", "synthetic:300x200", "-o", dir_ + "out.tess", "--threads", "100000"});
  ASSERT_TRUE(result.exited) << "killed by signal " << result.signal;
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_EQ(result.err, "tessera: 100000 threads out of 0..1024 (0 = one per core)\n");
  Outcome serve = run({"serve", dir_, "--threads", "100000"});
  ASSERT_TRUE(serve.exited);
  EXPECT_EQ(serve.exit_code, 2);
  EXPECT_NE(serve.err.find("--threads"), std::string::npos) << serve.err;
}

TEST_F(HostileCli, BadNumbersAreUsageErrorsThatSayWhatIsAccepted) {
  const std::string archive = smallArchive();
  const std::string out = dir_ + "x.tess", png = dir_ + "x.png";
  struct Case {
    std::vector<std::string> args;
    std::string expected;  ///< in stderr
  };
  const std::vector<Case> cases = {
      {{"build", "synthetic:10x10", "-o", out, "--quality", "0"}, "quality 0 out of 1..100"},
      {{"build", "synthetic:10x10", "-o", out, "--quality", "101"}, "quality 101 out of 1..100"},
      {{"build", "synthetic:10x10", "-o", out, "--codec", "zstd", "--effort", "99"},
       "effort 99 out of -100..22 for codec zstd"},
      {{"build", "synthetic:10x10", "-o", out, "--codec", "png", "--effort", "10"},
       "effort 10 out of 0..9 for codec png"},
      {{"build", "synthetic:10x10", "-o", out, "--codec", "webp", "--effort", "-1"},
       "effort -1 out of 0..9 for codec webp"},
      {{"build", "synthetic:10x10", "-o", out, "--codec", "ptm", "--effort", "7"},
       "effort 7 out of 0..4 for codec ptm"},
      {{"build", "synthetic:10x10", "-o", out, "--effort", "3"},
       "codec jpeg has no effort setting"},
      {{"build", "synthetic:10x10", "-o", out, "--tile", "100"}, "tile size 100 is not a power"},
      {{"build", "synthetic:10x10", "-o", out, "--border", "17"}, "border 17 out of 0..16"},
      {{"build", "synthetic:10x10", "-o", out, "--page-tiles-log2", "9"}, "2^9 out of 2^3..2^8"},
      {{"build", "synthetic:10x10", "-o", out, "--memory-limit", "lots"},
       "--memory-limit 'lots': expected a size such as 512M"},
      {{"build", "synthetic:10x10", "-o", out, "--memory-limit", "0"}, "--memory-limit '0'"},
      {{"serve", dir_, "--port", "99999"}, "--port: Value 99999 not in range 0 to 65535"},
      {{"serve", dir_, "--port", "-1"}, "not in range 0 to 65535"},
      {{"render", archive, "--centre", "10,10", "-o", png, "--texels-per-pixel", "nan"},
       "--texels-per-pixel must be above 0"},
      {{"render", archive, "--centre", "10,10", "-o", png, "--texels-per-pixel", "-1"},
       "--texels-per-pixel must be above 0"},
      {{"render", archive, "--centre", "inf,10", "-o", png}, "--centre must be two finite"},
      {{"render", archive, "--centre", "10,10", "-o", png, "--viewport", "0x64"}, "--viewport"},
  };
  for (const Case& c : cases) {
    Outcome result = run(c.args);
    std::string joined;
    for (const std::string& arg : c.args) joined += arg + " ";
    ASSERT_TRUE(result.exited) << joined;
    EXPECT_EQ(result.exit_code, 2) << joined << "\n" << result.err;
    EXPECT_NE(result.err.find(c.expected), std::string::npos) << joined << "\n" << result.err;
  }
  EXPECT_FALSE(std::filesystem::exists(out));
  EXPECT_FALSE(std::filesystem::exists(png));
}

// ---- Outputs never replace a special file --------------------------------------------------

TEST_F(HostileCli, FifosAndDeviceNodesAtTheOutputAreRefusedAndKept) {
  const std::string archive = smallArchive();
  std::vector<std::pair<std::string, mode_t>> nodes;
  ASSERT_EQ(::mkfifo((dir_ + "fifo").c_str(), 0644), 0);
  nodes.push_back({dir_ + "fifo", S_IFIFO});
  // A private copy of /dev/null (1, 3), where root may make one: the real node is never used.
  if (::mknod((dir_ + "null").c_str(), S_IFCHR | 0666, makedev(1, 3)) == 0)
    nodes.push_back({dir_ + "null", S_IFCHR});
  for (const auto& [node, type] : nodes) {
    const std::vector<std::vector<std::string>> commands = {
        {"build", "synthetic:300x200", "-o", node, "-q"},
        {"build", "synthetic-scene:20:4", "-o", node, "-q"},
        {"extract", archive, "--tile", "0,0", "-o", node},
        {"extract", archive, "--rect", "0,0,10,10", "-o", node},
        {"render", archive, "--centre", "150,100", "-o", node},
    };
    for (const auto& args : commands) {
      Outcome result = run(args);
      ASSERT_TRUE(result.exited) << args[0] << " " << node;
      EXPECT_EQ(result.exit_code, 2) << args[0] << " " << args[1] << ": " << result.err;
      EXPECT_NE(result.err.find(node + ": exists and is a"), std::string::npos) << result.err;
      EXPECT_NE(result.err.find("not a regular file; refusing to replace it"), std::string::npos)
          << result.err;
      EXPECT_EQ(fileType(node), type) << args[0] << " " << args[1] << " replaced " << node;
    }
  }
  std::vector<std::string> left;
  for (const auto& entry : std::filesystem::directory_iterator(dir_))
    left.push_back(entry.path().filename().string());
  std::sort(left.begin(), left.end());
  std::vector<std::string> expected = {"fifo", "small.tess"};
  if (nodes.size() == 2) expected = {"fifo", "null", "small.tess"};
  EXPECT_EQ(left, expected);
}

// Opening a FIFO for reading waits for a writer: every command that reads a file must refuse
// one (and a scene or placement list naming one) instead of hanging. A regression shows as
// this test timing out.
TEST_F(HostileCli, FifosAsInputsAreRefusedWithoutWaitingForAWriter) {
  const std::string archive = smallArchive();
  for (const char* name : {"in", "in.tif", "in.stg", "in.gltf", "in.dzi"})
    ASSERT_EQ(::mkfifo((dir_ + name).c_str(), 0644), 0);
  const std::string fifo = dir_ + "in";
  const std::vector<std::vector<std::string>> commands = {
      {"info", fifo},
      {"verify", fifo},
      {"build", fifo, "-o", dir_ + "a.tess"},
      {"build", dir_ + "in.tif", "-o", dir_ + "a.tess"},
      {"build", dir_ + "in.stg", "-o", dir_ + "a.tess"},
      {"build", dir_ + "in.gltf", "-o", dir_ + "a.tess"},
      {"build", dir_ + "in.dzi", "-o", dir_ + "a.tess"},
      {"merge", fifo, "-o", dir_ + "a.tess"},
      {"export", fifo, "--to", "pmtiles", dir_ + "a.pmtiles"},
      {"extract", fifo, "--tile", "0,0", "-o", dir_ + "a.png"},
      {"append", fifo, "synthetic:50x50"},
      {"update", archive, fifo, "--at", "0,0"},
      {"compact", fifo},
      {"serve", archive, "--access", fifo, "--port", "0"},
      {"serve", archive, "--tls-cert", fifo, "--tls-key", archive, "--port", "0"},
  };
  for (const auto& args : commands) {
    Outcome result = run(args);
    ASSERT_TRUE(result.exited) << args[0] << " " << args[1];
    EXPECT_NE(result.exit_code, 0) << args[0] << " " << args[1];
    EXPECT_NE(result.err.find("not a regular file"), std::string::npos)
        << args[0] << " " << args[1] << ": " << result.err;
  }
  EXPECT_FALSE(std::filesystem::exists(dir_ + "a.tess"));
}

// ---- Names: suggestions, spellings, lists --------------------------------------------------

TEST_F(HostileCli, AMisspeltSubcommandGetsTheNearestOne) {
  Outcome result = run({"biuld", "x"});
  EXPECT_EQ(result.exit_code, 2);
  // The list grows with the subcommands: checked by its start, its members and one line.
  EXPECT_EQ(result.err.rfind("tessera: unknown subcommand 'biuld' (did you mean 'build'?); it "
                             "must be one of build, info, verify, merge, extract, fly, demo, "
                             "view, render, serve",
                             0),
            0u)
      << result.err;
  EXPECT_NE(result.err.find(" or "), std::string::npos) << result.err;
  EXPECT_EQ(result.err.find('\n'), result.err.size() - 1) << result.err;
  Outcome far = run({"frobnicate"});
  EXPECT_EQ(far.exit_code, 2);
  EXPECT_EQ(far.err.find("did you mean"), std::string::npos) << far.err;
  EXPECT_NE(far.err.find("it must be one of build, info"), std::string::npos) << far.err;
  EXPECT_NE(run({"extarct"}).err.find("did you mean 'extract'?"), std::string::npos);
}

TEST_F(HostileCli, CommonSpellingsAreAcceptedAndUnknownValuesListTheChoices) {
  for (const std::vector<std::string>& extra : {std::vector<std::string>{"--codec", "jpg"},
                                                {"--codec", "JPEG", "--chroma", "4:4:4"},
                                                {"--codec", "zst", "--order", "row_major"},
                                                {"--order", "Row-Major"}}) {
    std::vector<std::string> args = {"build", "synthetic:100x80", "-o", dir_ + "s.tess", "-q"};
    args.insert(args.end(), extra.begin(), extra.end());
    Outcome result = run(args);
    EXPECT_EQ(result.exit_code, 0) << extra[1] << ": " << result.err;
  }
  Outcome center = run({"render", dir_ + "s.tess", "--center", "50,40", "-o", dir_ + "c.png"});
  EXPECT_EQ(center.exit_code, 0) << center.err;

  const std::vector<std::pair<std::vector<std::string>, std::string>> unknown = {
      {{"--codec", "gif"},
       "--codec 'gif' is not one of raw, zstd, lz4, jpeg, png, webp, ptm, zdelta, bc1 or bc7"},
      {{"--codec", "zsdt"}, "(did you mean 'zstd'?)"},
      {{"--order", "spiral"}, "--order 'spiral' is not one of hilbert, quadtree or row-major"},
      {{"--chroma", "411"}, "--chroma '411' is not one of 420 or 444"},
  };
  for (const auto& [extra, expected] : unknown) {
    std::vector<std::string> args = {"build", "synthetic:10x10", "-o", dir_ + "u.tess"};
    args.insert(args.end(), extra.begin(), extra.end());
    Outcome result = run(args);
    EXPECT_EQ(result.exit_code, 2) << extra[1];
    EXPECT_NE(result.err.find(expected), std::string::npos) << result.err;
  }
}

TEST_F(HostileCli, ServeSaysWhyAPathCannotBeServed) {
  Outcome missing = run({"serve", dir_ + "no-such-folder"});
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_EQ(missing.err, "tessera: " + dir_ +
                             "no-such-folder: cannot serve it: " + std::strerror(ENOENT) + "\n");
  ASSERT_EQ(::mkfifo((dir_ + "fifo").c_str(), 0644), 0);
  Outcome fifo = run({"serve", dir_ + "fifo"});
  EXPECT_EQ(fifo.exit_code, 2);
  EXPECT_NE(fifo.err.find("neither an archive file nor a folder"), std::string::npos) << fifo.err;
}

// ---- extract: edge tiles and rectangles ----------------------------------------------------

TEST_F(HostileCli, ExtractCropsEdgeTilesToTheImageUnlessAskedForThePadding) {
  const std::string archive = smallArchive();  // 300 x 200: tiles 5 x 4, the last 44 x 8
  struct Case {
    std::vector<std::string> flags;
    std::string tile;
    std::string size;
  };
  const std::vector<Case> cases = {
      {{}, "4,3", "44x8"},
      {{"--with-padding"}, "4,3", "64x64"},
      {{"--with-border"}, "4,3", "46x10"},  // the border inside the image only
      {{"--with-border", "--with-padding"}, "4,3", "68x68"},
      {{}, "1,1", "64x64"},
      {{"--with-border"}, "1,1", "68x68"},
      {{"--with-border"}, "0,0", "66x66"},  // no border left of or above the image
  };
  for (const Case& c : cases) {
    std::vector<std::string> args = {"extract", archive, "--tile", c.tile, "-o", dir_ + "t.png"};
    args.insert(args.end(), c.flags.begin(), c.flags.end());
    Outcome result = run(args);
    ASSERT_EQ(result.exit_code, 0) << result.err;
    EXPECT_NE(result.out.find(": " + c.size + ", 4 channel(s)"), std::string::npos)
        << c.tile << " " << (c.flags.empty() ? "" : c.flags[0]) << ": " << result.out;
    Image image = test::readImagePng(dir_ + "t.png");
    EXPECT_EQ(std::to_string(image.width_px) + "x" + std::to_string(image.height_px), c.size);
  }
  Outcome outside = run({"extract", archive, "--tile", "5,0", "-o", dir_ + "t5.png"});
  EXPECT_EQ(outside.exit_code, 2);
  EXPECT_NE(outside.err.find("--tile 5,0 is outside level 0, which has 5 x 4 tiles"),
            std::string::npos)
      << outside.err;
}

TEST_F(HostileCli, ExtractRefusesARectangleOutsideTheLevel) {
  const std::string archive = smallArchive();
  for (const std::string rect : {"5000,5000,10,10", "-5,10,100,60", "250,150,60,10"}) {
    Outcome result = run({"extract", archive, "--rect", rect, "-o", dir_ + "r.png"});
    EXPECT_EQ(result.exit_code, 2) << rect;
    EXPECT_NE(result.err.find("--rect " + rect + " is not inside level 0 (300 x 200 px)"),
              std::string::npos)
        << result.err;
    EXPECT_FALSE(std::filesystem::exists(dir_ + "r.png"));
  }
  Outcome inside = run({"extract", archive, "--rect", "290,190,10,10", "-o", dir_ + "r.png"});
  EXPECT_EQ(inside.exit_code, 0) << inside.err;
  Outcome padded =
      run({"extract", archive, "--rect", "-5,10,100,60", "--with-padding", "-o", dir_ + "p.png"});
  EXPECT_EQ(padded.exit_code, 0) << padded.err;
  Outcome deep = run({"extract", archive, "--level", "9", "--tile", "0,0", "-o", dir_ + "d.png"});
  EXPECT_EQ(deep.exit_code, 2);
  EXPECT_NE(deep.err.find("--level 9 but image 0 has levels 0..3"), std::string::npos) << deep.err;
}

// ---- Metadata: free-form JSON, read without throwing ----------------------------------------

// The metadata block is checked at open only to be one object. info shows informational
// fields of another type as they are, or skips them; the update record, which `update` counts
// on from, is refused naming the file and the field. Each threw from the JSON library before
// ("internal error").
TEST_F(HostileCli, InfoShowsFreeFormMetadataAndRefusesADamagedUpdateRecord) {
  const std::vector<uint8_t> bytes = test::readFileBytes(smallArchive());
  const std::string path = dir_ + "meta.tess";
  const struct {
    const char* metadata;
    const char* shown;  ///< a line of the output
  } free_form[] = {
      {R"({"format_version":2,"images":{"0":{"georeference":1}}})", "Tessera archive 2, "},
      {R"({"images":[5]})", "Tessera archive 1.0, "},
      {R"({"images":[{"georeference":[1]}]})", "\n  georeference: [1]\n"},
  };
  for (const auto& c : free_form) {
    ASSERT_TRUE(test::writeFileBytes(path, test::withMetadata(bytes, c.metadata)));
    Outcome shown = run({"info", path, "--no-levels"});
    ASSERT_TRUE(shown.exited) << c.metadata << ": killed by signal " << shown.signal;
    EXPECT_EQ(shown.exit_code, 0) << c.metadata << ": " << shown.err;
    EXPECT_EQ(shown.err, "") << c.metadata;
    EXPECT_NE(shown.out.find(c.shown), std::string::npos) << c.metadata << ": " << shown.out;
    EXPECT_EQ(shown.out.find("georeference: 1"), std::string::npos) << "not an image's entry";
  }
  Outcome json = run({"info", path, "--json", "--no-levels"});
  EXPECT_EQ(json.exit_code, 0) << json.err;

  const struct {
    const char* metadata;
    std::string error;
  } damaged[] = {
      {R"({"update":{"version":"2"}})",
       R"(metadata "update.version" is not an unsigned integer (it is "2"))"},
      {R"({"update":{"version":3,"dead_bytes":-5}})",
       R"(metadata "update.dead_bytes" is not an unsigned integer (it is -5))"},
  };
  for (const auto& c : damaged) {
    ASSERT_TRUE(test::writeFileBytes(path, test::withMetadata(bytes, c.metadata)));
    Outcome refused = run({"info", path, "--no-levels"});
    ASSERT_TRUE(refused.exited) << c.metadata << ": killed by signal " << refused.signal;
    EXPECT_EQ(refused.exit_code, 1) << c.metadata;
    EXPECT_EQ(refused.err, "tessera: " + path + ": " + c.error + "\n");
  }
}

// ---- Signals --------------------------------------------------------------------------------

TEST_F(HostileCli, SigtermExits143AndSigintExits130LeavingNothing) {
  // Long enough to be interrupted: 900 megapixels on one thread.
  for (const auto& [signal_number, code] : {std::pair{SIGTERM, 143}, std::pair{SIGINT, 130}}) {
    Outcome result = runTessera(
        {"build", "synthetic:30000x30000", "-o", dir_ + "big.tess", "-q", "--threads", "1"}, logs_,
        std::chrono::milliseconds(1000), signal_number);
    ASSERT_TRUE(result.exited) << "killed by signal " << result.signal;
    EXPECT_EQ(result.exit_code, code) << result.err;
    EXPECT_NE(result.err.find("build cancelled"), std::string::npos) << result.err;
    EXPECT_TRUE(std::filesystem::is_empty(dir_));
  }
}

TEST_F(HostileCli, HelpListsTheExitCodes) {
  Outcome help = run({"--help"});
  EXPECT_EQ(help.exit_code, 0);
  EXPECT_NE(help.out.find("130 interrupted by SIGINT, 143 stopped by SIGTERM"), std::string::npos)
      << help.out;
}

}  // namespace
}  // namespace tessera
