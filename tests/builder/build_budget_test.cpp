// The build's budget: the memory estimate against the figures docs/builder.md measured, hostile
// headers refused before anything is allocated with a message naming the file, its claimed
// size and the memory it needs, and the free-space check for spool and archive.
#include "builder/build_budget.h"

#include <sys/stat.h>

#include <filesystem>

#include <gtest/gtest.h>

#include <tessera/build.h>

#include "builder/band_reader.h"
#include "support/test_images.h"

namespace tessera::detail {
namespace {

constexpr uint64_t kMiB = uint64_t(1) << 20;

ImageInfo imageOf(uint32_t width, uint32_t height, uint32_t channels, uint32_t tile = 256,
                  uint32_t border = 0) {
  ImageInfo info;
  info.width_px = width;
  info.height_px = height;
  info.channels = channels;
  info.tile_size_px = tile;
  info.border_px = border;
  info.level_count = levelCountFor(width, height, tile);
  return info;
}

MemoryEstimate estimateFor(const std::string& source, Codec codec, uint32_t threads,
                           uint32_t tile = 256) {
  auto reader = openBandReader(source);
  EXPECT_TRUE(reader) << reader.error().message;
  const SourceInfo& info = (*reader)->info();
  const ImageInfo image = imageOf(info.width_px, info.height_px, info.channels, tile);
  const SourceInfo* sources[] = {&info};
  return estimateBuildMemory({&image, 1}, sources, codec, threads);
}

TEST(BuildBudget, AWideImageIsEstimatedAboveItsMeasuredPeak) {
  // docs/builder.md: synthetic:131072x4096:1:4 with 256-px tiles peaked at 409 MiB on 2 threads
  // (398 MiB in an earlier session), most of it the input band (128 MiB) and the pyramid's bands
  // (250 MiB: the levels of 256 rows and more, then the short ones).
  const MemoryEstimate estimate = estimateFor("synthetic:131072x4096:1:4", Codec::kJpeg, 2);
  EXPECT_GE(estimate.rows_bytes, 378 * kMiB);
  EXPECT_LE(estimate.rows_bytes, 400 * kMiB);
  EXPECT_GE(estimate.totalBytes(), 409 * kMiB);
  EXPECT_LE(estimate.totalBytes(), 520 * kMiB);
  EXPECT_LT(estimate.directory_bytes, 4 * kMiB);  // 11 k tiles
}

TEST(BuildBudget, PtmAddsTheTileRowsHeldForTheirParents) {
  // Measured: 717 MiB for ptm against 404 MiB for jpeg on the image above.
  const MemoryEstimate jpeg = estimateFor("synthetic:131072x4096:1:4", Codec::kJpeg, 2);
  const MemoryEstimate ptm = estimateFor("synthetic:131072x4096:1:4", Codec::kPtm, 2);
  EXPECT_GE(ptm.totalBytes(), 717 * kMiB);
  EXPECT_GE(ptm.rows_bytes, jpeg.rows_bytes + 3 * 128 * kMiB);  // three level-0 tile rows
}

TEST(BuildBudget, ThreadsAndTheTileDirectoryAreCounted) {
  const MemoryEstimate few = estimateFor("synthetic:4096x4096", Codec::kJpeg, 2);
  const MemoryEstimate many = estimateFor("synthetic:4096x4096", Codec::kJpeg, 1024);
  // Per encoder: a spool chunk that may double, its tiles and codec state.
  EXPECT_GE(many.tiles_bytes - few.tiles_bytes, 1022 * (8 * kMiB));
  // 16777216^2 px in 256-px tiles: 5.7e9 tiles, about 100 bytes each.
  const ImageInfo huge = imageOf(kMaxImageSidePx, kMaxImageSidePx, 4);
  SourceInfo source;
  const SourceInfo* sources[] = {&source};
  const MemoryEstimate estimate = estimateBuildMemory({&huge, 1}, sources, Codec::kJpeg, 1);
  EXPECT_GT(estimate.directory_bytes, uint64_t(500) << 30);
  EXPECT_GT(estimate.rows_bytes, uint64_t(48) << 30);  // 256 rows x 2^24 px x 4, and the levels
}

TEST(BuildBudget, TheBandIsATileOrTheReadersNaturalBand) {
  SourceInfo source;
  source.natural_band_rows = 16;
  EXPECT_EQ(bandRowsFor(imageOf(1000, 1000, 3), source), 256u);
  source.natural_band_rows = 512;
  EXPECT_EQ(bandRowsFor(imageOf(1000, 1000, 3), source), 512u);
  source.natural_band_rows = 4096;
  EXPECT_EQ(bandRowsFor(imageOf(1000, 5000, 3), source), 1024u);
  EXPECT_EQ(bandRowsFor(imageOf(1000, 100, 3), source), 100u);
}

TEST(BuildBudget, AnEstimateOverTheLimitNamesTheFileItsSizeAndTheMemory) {
  const ImageInfo infos[] = {imageOf(300, 200, 3), imageOf(2000000, 2000000, 4)};
  SourceInfo small, large;
  const SourceInfo* sources[] = {&small, &large};
  const MemoryEstimate estimate = estimateBuildMemory(infos, sources, Codec::kJpeg, 2);
  EXPECT_EQ(estimate.costliest_image, 1u);
  const std::string inputs[] = {"a.png", "claims-a-lot.png"};
  Result<void> checked = checkMemoryBudget(estimate, 8ull << 30, "--memory-limit", infos, inputs);
  ASSERT_FALSE(checked);
  EXPECT_EQ(checked.error().code, ErrorCode::kTooLarge);
  const std::string& message = checked.error().message;
  EXPECT_EQ(message.rfind("claims-a-lot.png: claims 2000000 x 2000000 px with 4 channel(s)", 0), 0u)
      << message;
  EXPECT_NE(message.find("with 1 other image(s)"), std::string::npos) << message;
  EXPECT_NE(message.find("needs about " + formatByteCount(estimate.totalBytes()) + " of memory"),
            std::string::npos)
      << message;
  EXPECT_NE(message.find("over the 8.0 GiB limit (--memory-limit)"), std::string::npos) << message;
  EXPECT_TRUE(checkMemoryBudget(estimate, estimate.totalBytes(), "x", infos, inputs));
}

TEST(BuildBudget, TheDefaultLimitIsHalfOfTheMachinesMemory) {
  const uint64_t usable = usableMemoryBytes();
  EXPECT_GT(usable, uint64_t(64) << 20);
  EXPECT_EQ(defaultBuildMemoryLimitBytes(), usable / 2);
}

TEST(BuildBudget, TheArchiveEstimateIsLowAndFollowsTheCodec) {
  const ImageInfo image = imageOf(1024, 1024, 4);
  const uint64_t pyramid = 1024 * 1024 * 4 * 4 / 3;
  EXPECT_EQ(estimateArchiveBytes({&image, 1}, Codec::kRaw, 85), pyramid);
  EXPECT_LT(estimateArchiveBytes({&image, 1}, Codec::kZstd, 85), pyramid / 3);
  EXPECT_LT(estimateArchiveBytes({&image, 1}, Codec::kJpeg, 85), pyramid / 40);
  EXPECT_GT(estimateArchiveBytes({&image, 1}, Codec::kJpeg, 100),
            estimateArchiveBytes({&image, 1}, Codec::kJpeg, 85));
}

TEST(BuildBudget, TooLittleFreeSpaceIsRefusedNamingTheDirectory) {
  const std::string dir = test::testTempDir();
  EXPECT_TRUE(checkFreeSpace(dir + "out.tess", dir, dir, 1 << 20));
  Result<void> checked = checkFreeSpace(dir + "out.tess", dir, dir, uint64_t(1) << 60);
  ASSERT_FALSE(checked);
  EXPECT_EQ(checked.error().code, ErrorCode::kIo);
  EXPECT_NE(checked.error().message.find("the spool and the archive need at least 2.0 EiB free "
                                         "in " +
                                         dir),
            std::string::npos)
      << checked.error().message;
}

// ---- Hostile headers through buildArchive ---------------------------------------------------

struct HostileCase {
  std::string name;
  std::vector<uint8_t> bytes;
};

/// A JPEG whose frame header claims 65500 x 65500 px over the data of a 16 x 16 image.
std::vector<uint8_t> jpegClaiming65500(const std::string& dir) {
  const std::string path = dir + "small.jpg";
  EXPECT_EQ(test::writeJpeg(path, {16, 16, 3, 90, false}, test::makeTestPixels(16, 16, 3)), "");
  std::vector<uint8_t> bytes = test::readFileBytes(path);
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

TEST(BuildBudget, HostileHeadersAreRefusedBeforeAnythingIsAllocated) {
  const std::string dir = test::testTempDir();
  const std::vector<HostileCase> cases = {
      {"huge.png", test::makePngHeaderOnly(kMaxImageSidePx, kMaxImageSidePx)},
      {"two-million.png", test::makePngHeaderOnly(2000000, 2000000)},
      {"huge.tif", test::makeRawTiffHeader(kMaxImageSidePx, kMaxImageSidePx, 16)},
      {"huge.jpg", jpegClaiming65500(dir)},
  };
  for (const HostileCase& c : cases) {
    ASSERT_TRUE(test::writeFileBytes(dir + c.name, c.bytes));
    BuildOptions options;
    options.inputs = {dir + c.name};
    options.output = dir + "out.tess";
    options.memory_limit_bytes = 128 * kMiB;
    options.threads = 2;
    auto report = buildArchive(options);
    ASSERT_FALSE(report) << c.name;
    EXPECT_EQ(report.error().code, ErrorCode::kTooLarge) << report.error().message;
    const std::string& message = report.error().message;
    EXPECT_EQ(message.rfind(dir + c.name + ": claims ", 0), 0u) << message;
    EXPECT_NE(message.find(" of memory"), std::string::npos) << message;
    EXPECT_NE(message.find("over the 128.0 MiB limit"), std::string::npos) << message;
    EXPECT_FALSE(std::filesystem::exists(options.output));
  }
  // Under the default limit (half of this machine's memory) the 2^24-px sides are refused too.
  BuildOptions options;
  options.inputs = {dir + "huge.png"};
  options.output = dir + "out.tess";
  auto report = buildArchive(options);
  ASSERT_FALSE(report);
  EXPECT_NE(report.error().message.find("claims 16777216 x 16777216 px"), std::string::npos)
      << report.error().message;
  EXPECT_NE(report.error().message.find("(the default: half of the"), std::string::npos)
      << report.error().message;
}

TEST(BuildBudget, AHeaderWithinTheBudgetFailsAtItsFirstRow) {
  // 65500 x 65500 RGB needs about 200 MiB here: under a 1 GiB limit the build starts, and the
  // missing data fails the first row (the rows were reserved, not written, so this is cheap).
  const std::string dir = test::testTempDir();
  ASSERT_TRUE(test::writeFileBytes(dir + "claims.jpg", jpegClaiming65500(dir)));
  BuildOptions options;
  options.inputs = {dir + "claims.jpg"};
  options.output = dir + "out.tess";
  options.memory_limit_bytes = uint64_t(1) << 30;
  options.threads = 2;
  auto report = buildArchive(options);
  ASSERT_FALSE(report);
  EXPECT_EQ(report.error().code, ErrorCode::kCorrupt) << report.error().message;
  EXPECT_NE(report.error().message.find("claims.jpg: row "), std::string::npos)
      << report.error().message;
  EXPECT_FALSE(std::filesystem::exists(options.output));
}

TEST(BuildBudget, TheLimitAndTheEstimateAreReported) {
  const std::string dir = test::testTempDir();
  BuildOptions options;
  options.inputs = {"synthetic:4096x4096"};
  options.output = dir + "out.tess";
  options.threads = 2;
  options.memory_limit_bytes = 16 * kMiB;
  auto refused = buildArchive(options);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("synthetic:4096x4096: claims 4096 x 4096 px"),
            std::string::npos)
      << refused.error().message;
  options.memory_limit_bytes = uint64_t(1) << 30;
  auto report = buildArchive(options);
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_EQ(report->memory_limit_bytes, uint64_t(1) << 30);
  EXPECT_GT(report->memory_estimate_bytes, 16 * kMiB);
  EXPECT_LT(report->memory_estimate_bytes, 200 * kMiB);
}

TEST(BuildBudget, TheSpoolGoesWhereItIsToldAndLeavesNothing) {
  const std::string dir = test::testTempDir();
  std::filesystem::create_directories(dir + "spool");
  std::filesystem::create_directories(dir + "out");
  BuildOptions options;
  options.inputs = {"synthetic:1000x700"};
  options.output = dir + "out/a.tess";
  options.spool_dir = dir + "spool";
  auto report = buildArchive(options);
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_TRUE(std::filesystem::is_empty(dir + "spool"));
  options.spool_dir = dir + "missing";
  auto missing = buildArchive(options);
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().message.find("spool: directory " + dir + "missing"), std::string::npos)
      << missing.error().message;
}

TEST(BuildBudget, ASpecialFileAtTheOutputIsRefusedBeforeTheInputsAreRead) {
  const std::string dir = test::testTempDir();
  ASSERT_EQ(::mkfifo((dir + "pipe").c_str(), 0644), 0);
  BuildOptions options;
  options.inputs = {dir + "missing.png"};  // never opened: the output fails first
  options.output = dir + "pipe";
  auto report = buildArchive(options);
  ASSERT_FALSE(report);
  EXPECT_EQ(report.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(report.error().message.find("pipe: exists and is a FIFO"), std::string::npos)
      << report.error().message;
  EXPECT_TRUE(std::filesystem::is_fifo(dir + "pipe"));
}

}  // namespace
}  // namespace tessera::detail
