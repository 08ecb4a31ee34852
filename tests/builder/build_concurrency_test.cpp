// Whole builds under ThreadSanitizer in CI (label "concurrency"): the encoders cut their tiles
// out of the pyramid's bands while the building thread reads on into them.
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include <tessera/build.h>
#include <tessera/split_build.h>

#include "support/test_images.h"

namespace tessera {
namespace {

std::vector<uint8_t> buildBytes(const std::string& path, Codec codec, uint32_t threads,
                                uint32_t border) {
  BuildOptions options;
  // Two images of odd sizes: the second's bands replace the first's while the pool is shared.
  options.inputs = {"synthetic:700x530:7:3", "synthetic:301x333:9:4"};
  options.output = path;
  options.codec = codec;
  options.tile_size_px = 64;
  options.border_px = border;
  options.threads = threads;
  auto report = buildArchive(options);
  EXPECT_TRUE(report) << report.error().message;
  return test::readFileBytes(path);
}

// More encoders than cores and one: the same bytes, whichever encoder cut which tile when.
TEST(BuildConcurrency, EncodersCuttingFromTheBandsGiveTheSameArchiveAsOne) {
  const std::string dir = test::testTempDir();
  const std::pair<Codec, uint32_t> cases[] = {{Codec::kJpeg, 0}, {Codec::kZstd, 2}};
  for (const auto& [codec, border] : cases) {
    const std::vector<uint8_t> one = buildBytes(dir + "one.tess", codec, 1, border);
    ASSERT_FALSE(one.empty());
    EXPECT_EQ(buildBytes(dir + "many.tess", codec, 6, border), one)
        << codecName(codec) << " border " << border;
  }
}

// A merge encodes the coarse levels on a worker pool and writes on a second thread while the
// next payloads are mapped from the parts: the same bytes as the single build.
TEST(BuildConcurrency, AMergeOfPartsGivesTheSingleBuildsArchive) {
  const std::string dir = test::testTempDir();
  BuildOptions options;
  options.inputs = {"synthetic:520x400:3:3"};
  options.tile_size_px = 64;
  options.codec = Codec::kZstd;
  options.threads = 2;
  options.output = dir + "single.tess";
  ASSERT_TRUE(buildArchive(options));
  std::vector<std::string> parts;
  for (uint32_t i = 1; i <= 3; ++i) {
    options.output = dir + "part-" + std::to_string(i) + ".tess";
    ASSERT_TRUE(buildArchivePart(options, {i, 3}));
    parts.push_back(options.output);
  }
  Result<MergeReport> merged = mergeArchiveParts(parts, dir + "merged.tess");
  ASSERT_TRUE(merged) << merged.error().message;
  EXPECT_GT(merged->tiles_computed, 0u);
  EXPECT_GT(merged->tiles_copied, 0u);
  EXPECT_TRUE(test::readFileBytes(dir + "single.tess") == test::readFileBytes(dir + "merged.tess"));
}

}  // namespace
}  // namespace tessera
