// updateRegion, appendImage and compactArchive against full builds of the same pixels: an
// update must equal, texel for texel, a build from the patched source (lossless codecs).
#include "update/archive_update.h"

#include <cstring>
#include <filesystem>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <tessera/archive.h>
#include <tessera/build.h>

#include "support/archive_fixture.h"
#include "support/test_images.h"

namespace tessera {
namespace {

using detail::UpdateReport;

/// An image in memory, built into archives through a RowSource.
struct SourcePixels {
  Image image;
  std::string name = "memory";
};

Image makeImage(uint32_t width, uint32_t height, uint32_t channels, uint32_t seed) {
  Image image(width, height, channels);
  image.texels = test::makeTestPixels(width, height, channels, seed);
  return image;
}

void paste(Image& into, const Image& patch, uint32_t x, uint32_t y) {
  for (uint32_t row = 0; row < patch.height_px; ++row)
    std::copy(patch.row(row), patch.row(row) + patch.strideBytes(),
              into.row(y + row) + size_t(x) * into.channels);
}

BuildOptions optionsFor(const std::string& output, Codec codec, uint32_t tile, uint32_t border) {
  BuildOptions options;
  options.output = output;
  options.codec = codec;
  options.tile_size_px = tile;
  options.border_px = border;
  options.threads = 2;
  return options;
}

void buildFrom(const std::vector<const Image*>& images, BuildOptions options) {
  for (const Image* image : images) {
    RowSource source;
    source.name = "memory";
    source.width_px = image->width_px;
    source.height_px = image->height_px;
    source.channels = image->channels;
    source.read_rows = [image](uint32_t first, uint32_t rows, std::span<uint8_t> out) {
      std::copy(image->row(first), image->row(first) + rows * image->strideBytes(), out.data());
      return Result<void>{};
    };
    options.row_sources.push_back(std::move(source));
  }
  Result<BuildReport> built = buildArchive(options);
  ASSERT_TRUE(built) << built.error().message;
}

std::shared_ptr<Archive> openOrDie(const std::string& path) {
  Result<std::shared_ptr<Archive>> archive = Archive::openFile(path);
  EXPECT_TRUE(archive) << archive.error().message;
  return archive ? *archive : nullptr;
}

/// Every tile of image `image` decodes to the same texels in both archives.
void expectSameTiles(const Archive& a, const Archive& b, uint32_t image_a, uint32_t image_b) {
  const ImageInfo& info = a.images()[image_a];
  for (uint32_t level = 0; level < info.level_count; ++level)
    for (uint32_t y = 0; y < info.tilesY(level); ++y)
      for (uint32_t x = 0; x < info.tilesX(level); ++x) {
        Result<Image> left = a.readTile({image_a, level, x, y});
        Result<Image> right = b.readTile({image_b, level, x, y});
        ASSERT_TRUE(left && right) << "tile " << level << "," << x << "," << y;
        ASSERT_EQ(left->texels, right->texels) << "tile (" << level << "," << x << "," << y << ")";
      }
}

struct UpdateCase {
  Codec codec;
  uint32_t width, height, channels, tile, border, x, y, patch_w, patch_h;
};

class UpdateEqualsRebuild : public ::testing::TestWithParam<UpdateCase> {};

TEST_P(UpdateEqualsRebuild, EveryTileOfEveryLevel) {
  const UpdateCase c = GetParam();
  const std::string dir = test::testTempDir();
  Image base = makeImage(c.width, c.height, c.channels, 3);
  const Image patch = makeImage(c.patch_w, c.patch_h, c.channels, 9);
  buildFrom({&base}, optionsFor(dir + "a.tess", c.codec, c.tile, c.border));
  std::shared_ptr<Archive> before = openOrDie(dir + "a.tess");
  Result<UpdateReport> report = detail::updateRegion(dir + "a.tess", 0, c.x, c.y, patch, "patch");
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_EQ(report->version, 2u);
  EXPECT_EQ(report->file_bytes, std::filesystem::file_size(dir + "a.tess"));
  paste(base, patch, c.x, c.y);
  buildFrom({&base}, optionsFor(dir + "b.tess", c.codec, c.tile, c.border));
  std::shared_ptr<Archive> updated = openOrDie(dir + "a.tess");
  std::shared_ptr<Archive> rebuilt = openOrDie(dir + "b.tess");
  EXPECT_TRUE(updated->verify().ok());
  expectSameTiles(*updated, *rebuilt, 0, 0);
  // The statistics describe the patched image, as the rebuild's do.
  const auto statistics = [](const Archive& archive) {
    return nlohmann::json::parse(archive.metadataJson())["images"][0]["statistics"];
  };
  EXPECT_FALSE(statistics(*rebuilt).is_null());
  EXPECT_EQ(statistics(*updated), statistics(*rebuilt));
  // Tiles far from the patch keep their stored payloads (nothing re-encoded there), and the
  // coarsest tile, an ancestor of every tile, was recomputed.
  const ImageInfo& info = updated->images()[0];
  const TileId far{0, 0, c.x < c.width / 2 ? info.tilesX(0) - 1 : 0,
                   c.y < c.height / 2 ? info.tilesY(0) - 1 : 0};
  const TileEntry far_before = *before->tileEntry(far);
  const TileEntry far_after = *updated->tileEntry(far);
  EXPECT_EQ(far_before.offset_bytes, far_after.offset_bytes);
  const TileId top{0, info.level_count - 1, 0, 0};
  EXPECT_NE(before->tileEntry(top)->checksum, updated->tileEntry(top)->checksum);
}

INSTANTIATE_TEST_SUITE_P(
    Geometries, UpdateEqualsRebuild,
    ::testing::Values(UpdateCase{Codec::kPng, 1000, 700, 3, 128, 2, 300, 200, 150, 90},
                      UpdateCase{Codec::kZstd, 777, 513, 4, 64, 0, 129, 63, 200, 101},
                      UpdateCase{Codec::kLz4, 901, 300, 1, 128, 3, 0, 0, 901, 1},
                      UpdateCase{Codec::kZstd, 640, 480, 2, 64, 1, 600, 470, 40, 10}));

TEST(Update, AReaderOpenAcrossAnUpdateKeepsReadingTheOldVersion) {
  const std::string dir = test::testTempDir();
  Image base = makeImage(500, 400, 3, 5);
  buildFrom({&base}, optionsFor(dir + "a.tess", Codec::kZstd, 64, 1));
  buildFrom({&base}, optionsFor(dir + "old.tess", Codec::kZstd, 64, 1));
  std::shared_ptr<Archive> reader = openOrDie(dir + "a.tess");
  const Image patch = makeImage(100, 100, 3, 11);
  for (uint32_t round = 0; round < 3; ++round)
    ASSERT_TRUE(detail::updateRegion(dir + "a.tess", 0, 50 * round, 40, patch, "patch"));
  // The reader took its header before the updates: it sees the old pixels, all of them.
  expectSameTiles(*reader, *openOrDie(dir + "old.tess"), 0, 0);
  EXPECT_TRUE(reader->verify().ok());
  std::shared_ptr<Archive> fresh = openOrDie(dir + "a.tess");
  EXPECT_NE(fresh->readTile({0, 0, 1, 1})->texels, reader->readTile({0, 0, 1, 1})->texels);
  EXPECT_NE(fresh->metadataJson().find("\"version\":4"), std::string::npos);
}

TEST(Update, AnUncommittedTailAndATornHeaderLeaveAVersionThatVerifies) {
  const std::string dir = test::testTempDir();
  const std::string path = dir + "a.tess";
  Image base = makeImage(300, 300, 3, 2);
  buildFrom({&base}, optionsFor(path, Codec::kPng, 64, 0));
  const Image patch = makeImage(30, 30, 3, 4);
  ASSERT_TRUE(detail::updateRegion(path, 0, 10, 10, patch, "patch"));
  std::vector<uint8_t> committed = test::readFileBytes(path);
  // An update killed before its header: a tail past file_bytes, which readers ignore.
  std::vector<uint8_t> with_tail = committed;
  with_tail.insert(with_tail.end(), 5000, 0xAB);
  ASSERT_TRUE(test::writeFileBytes(path, with_tail));
  EXPECT_TRUE(openOrDie(path)->verify().ok());
  // A torn header write (the copy at the end was synced first): readers use the copy.
  std::vector<uint8_t> torn = committed;
  for (size_t i = 16; i < 64; ++i) torn[i] ^= 0x5A;
  ASSERT_TRUE(test::writeFileBytes(path, torn));
  std::shared_ptr<Archive> recovered = openOrDie(path);
  ASSERT_TRUE(recovered);
  EXPECT_TRUE(recovered->verify().ok());
  EXPECT_EQ(recovered->fileBytes(), committed.size());
  // The next update repairs the header and cuts nothing it needs.
  ASSERT_TRUE(detail::updateRegion(path, 0, 100, 100, patch, "patch"));
  std::vector<uint8_t> repaired = test::readFileBytes(path);
  EXPECT_TRUE(openOrDie(path)->verify().ok());
}

TEST(Update, MalformedRequestsFailNamingTheProblemAndLeaveTheFileAlone) {
  const std::string dir = test::testTempDir();
  const std::string path = dir + "a.tess";
  Image base = makeImage(200, 100, 3, 2);
  buildFrom({&base}, optionsFor(path, Codec::kZstd, 64, 0));
  const std::vector<uint8_t> original = test::readFileBytes(path);
  auto message = [&](uint32_t image, uint32_t x, uint32_t y, const Image& patch) {
    Result<UpdateReport> report = detail::updateRegion(path, image, x, y, patch, "patch.png");
    return report ? std::string("accepted") : report.error().message;
  };
  EXPECT_NE(message(0, 190, 0, makeImage(20, 5, 3, 1)).find("reaches outside image 0"),
            std::string::npos);
  EXPECT_NE(message(0, 0, 99, makeImage(1, 2, 3, 1)).find("reaches outside"), std::string::npos);
  EXPECT_NE(message(1, 0, 0, makeImage(5, 5, 3, 1)).find("no image 1"), std::string::npos);
  EXPECT_NE(message(0, 0, 0, makeImage(5, 5, 4, 1)).find("patch.png: 4 channels"),
            std::string::npos);
  EXPECT_NE(message(0, 0, 0, Image(0, 0, 3)).find("empty patch"), std::string::npos);
  EXPECT_EQ(test::readFileBytes(path), original);
  buildFrom({&base}, optionsFor(dir + "p.tess", Codec::kPtm, 64, 0));
  Result<UpdateReport> ptm =
      detail::updateRegion(dir + "p.tess", 0, 0, 0, makeImage(5, 5, 3, 1), "x");
  ASSERT_FALSE(ptm);
  EXPECT_EQ(ptm.error().code, ErrorCode::kUnsupported);
  test::writeFileBytes(dir + "junk.tess", std::vector<uint8_t>(5000, 7));
  EXPECT_FALSE(detail::updateRegion(dir + "junk.tess", 0, 0, 0, makeImage(5, 5, 3, 1), "x"));
}

// The next version counts on from the stored record, and re-encoded tiles take the build's
// settings: a damaged one is refused by name (it threw from the JSON library before), and the
// file is left as it was.
TEST(Update, ADamagedUpdateRecordOrBuildSettingIsRefusedNamingTheField) {
  const std::string path = test::testTempDir() + "damaged-record.tess";
  Image base = makeImage(100, 60, 3, 4);
  buildFrom({&base}, optionsFor(path, Codec::kZstd, 64, 0));
  const std::vector<uint8_t> built = test::readFileBytes(path);
  const struct {
    const char* metadata;
    const char* message;
  } cases[] = {
      {R"({"update":{"version":"2","dead_bytes":0}})",
       R"(: metadata "update.version" is not an unsigned integer (it is "2"))"},
      {R"({"build":{"quality":"high"}})",
       R"(: metadata "build.quality" is not an integer (it is "high"))"},
  };
  for (const auto& c : cases) {
    ASSERT_TRUE(test::writeFileBytes(path, test::withMetadata(built, c.metadata)));
    const std::vector<uint8_t> before = test::readFileBytes(path);
    Result<UpdateReport> report = detail::updateRegion(path, 0, 0, 0, makeImage(5, 5, 3, 1), "x");
    ASSERT_FALSE(report) << c.metadata;
    EXPECT_EQ(report.error().code, ErrorCode::kCorrupt);
    EXPECT_EQ(report.error().message, path + c.message);
    EXPECT_EQ(test::readFileBytes(path), before) << c.metadata;
  }
}

// The updater averages and cuts 8-bit texels only: wider images and patches are refused by
// name, and the archive is left byte for byte as it was.
TEST(Update, WideImagesAndPatchesAreRefusedNamingTheSampleType) {
  const std::string dir = test::testTempDir();
  std::vector<uint16_t> wide(size_t(120) * 80);
  for (size_t i = 0; i < wide.size(); ++i) wide[i] = uint16_t(i * 37);
  BuildOptions options = optionsFor(dir + "wide.tess", Codec::kZstd, 64, 0);
  RowSource source;
  source.name = "memory16";
  source.width_px = 120;
  source.height_px = 80;
  source.channels = 1;
  source.sample_type = SampleType::kU16;
  source.read_rows = [&wide](uint32_t first, uint32_t rows, std::span<uint8_t> out) {
    std::memcpy(out.data(), wide.data() + size_t(first) * 120, size_t(rows) * 120 * 2);
    return Result<void>{};
  };
  options.row_sources.push_back(std::move(source));
  ASSERT_TRUE(buildArchive(options));
  const std::vector<uint8_t> original = test::readFileBytes(dir + "wide.tess");
  Result<UpdateReport> update =
      detail::updateRegion(dir + "wide.tess", 0, 0, 0, makeImage(5, 5, 1, 1), "patch.png");
  ASSERT_FALSE(update);
  EXPECT_EQ(update.error().code, ErrorCode::kUnsupported);
  EXPECT_NE(update.error().message.find("u16 or f32 samples"), std::string::npos)
      << update.error().message;
  EXPECT_EQ(test::readFileBytes(dir + "wide.tess"), original);

  Image narrow = makeImage(100, 60, 1, 4);
  buildFrom({&narrow}, optionsFor(dir + "a.tess", Codec::kZstd, 64, 0));
  const std::vector<uint8_t> narrow_bytes = test::readFileBytes(dir + "a.tess");
  test::PngSpec spec;
  spec.width_px = 30;
  spec.height_px = 20;
  spec.colour = test::PngColour::kGray;
  spec.bit_depth = 16;
  ASSERT_EQ(test::writePng(dir + "wide.png", spec, std::vector<uint8_t>(600, 9)), "");
  BuildOptions append = optionsFor("", Codec::kZstd, 64, 0);
  append.inputs = {dir + "wide.png"};
  Result<UpdateReport> appended = detail::appendImage(dir + "a.tess", append);
  ASSERT_FALSE(appended);
  EXPECT_EQ(appended.error().code, ErrorCode::kUnsupported);
  EXPECT_NE(appended.error().message.find("wide.png has u16 samples"), std::string::npos)
      << appended.error().message;
  EXPECT_EQ(test::readFileBytes(dir + "a.tess"), narrow_bytes);
}

TEST(Append, TheAddedImageEqualsABuildOfItAndTheOthersAreUntouched) {
  const std::string dir = test::testTempDir();
  Image first = makeImage(400, 300, 3, 2);
  Image second = makeImage(333, 222, 3, 8);
  buildFrom({&first}, optionsFor(dir + "a.tess", Codec::kPng, 64, 1));
  const std::string second_path = dir + "second.png";
  test::PngSpec spec;
  spec.width_px = second.width_px;
  spec.height_px = second.height_px;
  test::writePng(second_path, spec, second.texels);
  BuildOptions options = optionsFor("", Codec::kPng, 64, 1);
  options.inputs = {second_path};
  Result<UpdateReport> report = detail::appendImage(dir + "a.tess", options);
  ASSERT_TRUE(report) << report.error().message;
  buildFrom({&first, &second}, optionsFor(dir + "both.tess", Codec::kPng, 64, 1));
  std::shared_ptr<Archive> appended = openOrDie(dir + "a.tess");
  std::shared_ptr<Archive> both = openOrDie(dir + "both.tess");
  ASSERT_EQ(appended->images().size(), 2u);
  EXPECT_TRUE(appended->verify().ok());
  expectSameTiles(*appended, *both, 0, 0);
  expectSameTiles(*appended, *both, 1, 1);
}

TEST(Compact, DropsDeadBytesAndKeepsEveryTexel) {
  const std::string dir = test::testTempDir();
  Image base = makeImage(600, 500, 3, 6);
  buildFrom({&base}, optionsFor(dir + "a.tess", Codec::kZstd, 64, 2));
  for (uint32_t round = 0; round < 4; ++round)
    ASSERT_TRUE(
        detail::updateRegion(dir + "a.tess", 0, 70 * round, 50, makeImage(90, 80, 3, round), "p"));
  const uint64_t updated_bytes = std::filesystem::file_size(dir + "a.tess");
  Result<detail::CompactReport> report = detail::compactArchive(dir + "a.tess", dir + "c.tess");
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_EQ(report->bytes_after, std::filesystem::file_size(dir + "c.tess"));
  EXPECT_LT(report->bytes_after, updated_bytes);
  std::shared_ptr<Archive> compacted = openOrDie(dir + "c.tess");
  EXPECT_TRUE(compacted->verify().ok());
  expectSameTiles(*compacted, *openOrDie(dir + "a.tess"), 0, 0);
  EXPECT_EQ(compacted->metadataJson().find("\"update\""), std::string::npos);
  // In place: the archive itself is replaced, and still updatable.
  ASSERT_TRUE(detail::compactArchive(dir + "a.tess", dir + "a.tess"));
  EXPECT_EQ(std::filesystem::file_size(dir + "a.tess"), report->bytes_after);
  EXPECT_TRUE(detail::updateRegion(dir + "a.tess", 0, 0, 0, makeImage(9, 9, 3, 1), "p"));
}

}  // namespace
}  // namespace tessera
