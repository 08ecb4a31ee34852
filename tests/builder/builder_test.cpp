// buildArchive end to end: the pyramid read back equals the independent reference pixel for
// pixel for every shape, tile size and border; bad inputs and failing outputs give clear
// errors and leave no file; cancellation leaves no file; a previous file survives failure.
#include <tessera/build.h>

#include <sys/mount.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <random>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <tessera/archive.h>

#include "support/archive_fixture.h"
#include "support/reference_pyramid.h"
#include "support/test_images.h"

namespace tessera {
namespace {

std::vector<std::string> listDir(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(dir))
    names.push_back(entry.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

std::string tileName(uint32_t level, uint32_t x, uint32_t y) {
  return "(" + std::to_string(level) + "," + std::to_string(x) + "," + std::to_string(y) + ")";
}

// ---- The pyramid against the reference ------------------------------------------------------

struct PyramidCase {
  const char* name;
  uint32_t width, height, channels;
  /// The synthetic source (3 or 4 channels; over 4 MP through a TIFF of it) rather than a PNG
  /// fixture of the test pattern.
  bool synthetic;
  Codec codec;
  std::vector<uint32_t> tile_sizes;
  std::vector<uint32_t> borders;
  /// When set, only these (tile size, border) pairs rather than every combination.
  std::vector<std::pair<uint32_t, uint32_t>> only = {};
};

void PrintTo(const PyramidCase& c, std::ostream* out) {
  *out << c.name;
}

const std::vector<uint32_t> kAllTileSizes = {64, 128, 256, 512, 1024, 2048};
const std::vector<uint32_t> kAllBorders = {0, 1, 4};

struct KindCounts {
  uint64_t empty = 0, uniform = 0, encoded = 0;
};

// Checks every tile (texels and kind) and random regions of an archive against `reference`.
KindCounts expectArchiveEqualsReference(const Archive& archive,
                                        const test::ReferencePyramid& reference) {
  KindCounts counts;
  const ImageInfo& info = archive.images()[0];
  EXPECT_EQ(info.level_count, reference.levelCount(info.tile_size_px));
  int failures = 0;
  for (uint32_t level = 0; level < info.level_count && failures < 3; ++level) {
    EXPECT_EQ(info.tilesX(level), reference.tilesX(level, info.tile_size_px));
    EXPECT_EQ(info.tilesY(level), reference.tilesY(level, info.tile_size_px));
    for (uint32_t y = 0; y < info.tilesY(level) && failures < 3; ++y) {
      for (uint32_t x = 0; x < info.tilesX(level) && failures < 3; ++x) {
        test::ReferenceTile expected =
            reference.tile(level, x, y, info.tile_size_px, info.border_px);
        auto entry = archive.tileEntry({0, level, x, y});
        auto tile = archive.readTile({0, level, x, y});
        if (!entry || !tile) {
          ADD_FAILURE() << "tile " << tileName(level, x, y) << ": "
                        << (!entry ? entry.error().message : tile.error().message);
          ++failures;
          continue;
        }
        std::string difference = test::firstDifference(expected.texels, *tile);
        if (!difference.empty() || entry->kind != expected.kind ||
            (expected.kind == TileKind::kUniform && entry->uniform_rgba != expected.uniform_rgba)) {
          ADD_FAILURE() << "tile " << tileName(level, x, y) << ": kind "
                        << tileKindName(entry->kind) << " (expected " << tileKindName(expected.kind)
                        << ") " << difference;
          ++failures;
        }
        switch (entry->kind) {
          case TileKind::kEmpty: ++counts.empty; break;
          case TileKind::kUniform: ++counts.uniform; break;
          default: ++counts.encoded; break;
        }
      }
    }
  }
  std::mt19937 random(info.tile_size_px + info.border_px);
  for (uint32_t level = 0; level < info.level_count; level += 2) {
    const int64_t w = info.levelWidthPx(level), h = info.levelHeightPx(level);
    for (int i = 0; i < 4; ++i) {
      int64_t x = std::uniform_int_distribution<int64_t>(-40, w)(random);
      int64_t y = std::uniform_int_distribution<int64_t>(-40, h)(random);
      uint32_t rw = std::uniform_int_distribution<uint32_t>(1, 300)(random);
      uint32_t rh = std::uniform_int_distribution<uint32_t>(1, 300)(random);
      auto region = archive.readRegion(0, level, {x, y, rw, rh});
      if (!region) {
        ADD_FAILURE() << region.error().message;
        continue;
      }
      EXPECT_EQ(test::firstDifference(reference.region(level, x, y, rw, rh), *region), "")
          << "level " << level << " rect " << x << "," << y << " " << rw << "x" << rh;
    }
  }
  return counts;
}

class BuiltPyramid : public testing::TestWithParam<PyramidCase> {};

TEST_P(BuiltPyramid, EqualsTheReferencePixelForPixel) {
  const PyramidCase& c = GetParam();
  const std::string dir = test::testTempDir();
  std::string source;
  Image image;
  if (c.synthetic) {
    source = "synthetic:" + std::to_string(c.width) + "x" + std::to_string(c.height) +
             ":3:" + std::to_string(c.channels);
    image = test::readSource(source);
    if (uint64_t(c.width) * c.height > (4u << 20)) {
      // Large: generate once and build each variant from an uncompressed TIFF of it.
      test::TiffSpec spec;
      spec.width_px = c.width;
      spec.height_px = c.height;
      spec.samples = uint16_t(c.channels);
      spec.rows_per_strip = 64;
      source = dir + "source.tif";
      ASSERT_EQ(test::writeTiff(source, spec, image.texels), "");
    }
  } else {
    source = dir + "source.png";
    image = test::makePatternImage(c.width, c.height, c.channels, c.width + c.height);
    ASSERT_EQ(test::writeImagePng(source, image), "");
  }
  ASSERT_EQ(image.channels, c.channels);
  const test::ReferencePyramid reference(std::move(image));
  std::vector<std::pair<uint32_t, uint32_t>> variants = c.only;
  if (variants.empty())
    for (uint32_t tile : c.tile_sizes)
      for (uint32_t border : c.borders) variants.push_back({tile, border});
  for (const auto& [tile, border] : variants) {
    {
      SCOPED_TRACE("tile " + std::to_string(tile) + " border " + std::to_string(border));
      BuildOptions options;
      options.inputs = {source};
      options.output = dir + "out.tess";
      options.tile_size_px = tile;
      options.border_px = border;
      options.codec = c.codec;
      options.threads = 2;
      auto report = buildArchive(options);
      ASSERT_TRUE(report) << report.error().message;
      auto archive = Archive::openFile(options.output);
      ASSERT_TRUE(archive) << archive.error().message;
      KindCounts counts = expectArchiveEqualsReference(**archive, reference);
      EXPECT_EQ(report->tiles_empty, counts.empty);
      EXPECT_EQ(report->tiles_uniform, counts.uniform);
      EXPECT_EQ(report->tiles_encoded, counts.encoded);
      EXPECT_EQ(report->output_bytes, (*archive)->fileBytes());
      if (testing::Test::HasFailure()) return;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(
    Shapes, BuiltPyramid,
    testing::Values(
        PyramidCase{"1x1_gray", 1, 1, 1, false, Codec::kZstd, kAllTileSizes, kAllBorders},
        PyramidCase{"1x1_rgba", 1, 1, 4, false, Codec::kRaw, {64, 2048}, {0, 4}},
        PyramidCase{"1x300_gray_alpha", 1, 300, 2, false, Codec::kZstd, kAllTileSizes, kAllBorders},
        PyramidCase{"300x1_rgb", 300, 1, 3, false, Codec::kLz4, kAllTileSizes, kAllBorders},
        PyramidCase{"257x513_rgba", 257, 513, 4, false, Codec::kZstd, kAllTileSizes, kAllBorders},
        PyramidCase{"257x513_gray_png", 257, 513, 1, false, Codec::kPng, {64, 256}, {0, 4}},
        PyramidCase{"1000x999_synthetic_rgb", 1000, 999, 3, true, Codec::kZstd, kAllTileSizes,
                    kAllBorders},
        PyramidCase{"1000x999_gray_alpha_webp", 1000, 999, 2, false, Codec::kWebp, {64, 512}, {1}},
        PyramidCase{"1000x999_rgba_raw", 1000, 999, 4, false, Codec::kRaw, {128}, {4}},
        PyramidCase{"4097x4095_synthetic_rgba",
                    4097,
                    4095,
                    4,
                    true,
                    Codec::kLz4,
                    {},
                    {},
                    {{64, 0}, {64, 4}, {256, 4}, {2048, 0}}}),
    [](const testing::TestParamInfo<PyramidCase>& param_info) { return param_info.param.name; });

TEST(Builder, ThePatternProducesEveryTileKind) {
  // Guards the pyramid tests above: they only prove kinds if all three occur.
  Image image = test::makePatternImage(257, 513, 4, 1);
  test::ReferencePyramid reference(image);
  KindCounts counts;
  for (uint32_t y = 0; y < reference.tilesY(0, 64); ++y) {
    for (uint32_t x = 0; x < reference.tilesX(0, 64); ++x) {
      switch (reference.tile(0, x, y, 64, 1).kind) {
        case TileKind::kEmpty: ++counts.empty; break;
        case TileKind::kUniform: ++counts.uniform; break;
        default: ++counts.encoded; break;
      }
    }
  }
  EXPECT_GT(counts.empty, 0u);
  EXPECT_GT(counts.uniform, 0u);
  EXPECT_GT(counts.encoded, 0u);
}

TEST(Builder, BordersEqualTheNeighboursTexels) {
  const uint32_t t = 64, b = 4;
  BuildOptions options;
  options.tile_size_px = t;
  options.border_px = b;
  options.codec = Codec::kZstd;
  options.threads = 2;
  test::BuiltArchive built =
      test::buildFromImage(test::makePatternImage(300, 220, 3, 8), options, test::testTempDir());
  auto archive = Archive::open(makeMemorySource(built.bytes, "b.tess"));
  ASSERT_TRUE(archive);
  const ImageInfo& info = (*archive)->images()[0];
  const uint32_t c = info.channels;
  for (uint32_t level = 0; level < info.level_count; ++level) {
    for (uint32_t y = 0; y < info.tilesY(level); ++y) {
      for (uint32_t x = 0; x < info.tilesX(level); ++x) {
        Image tile = *(*archive)->readTile({0, level, x, y});
        if (x + 1 < info.tilesX(level)) {
          Image right = *(*archive)->readTile({0, level, x + 1, y});
          for (uint32_t row = 0; row < t + 2 * b; ++row) {
            // Our right border is the right tile's first interior columns, and vice versa.
            ASSERT_TRUE(std::equal(tile.row(row) + (b + t) * c, tile.row(row) + (2 * b + t) * c,
                                   right.row(row) + b * c))
                << tileName(level, x, y) << " right border, row " << row;
            ASSERT_TRUE(std::equal(right.row(row), right.row(row) + b * c, tile.row(row) + t * c))
                << tileName(level, x + 1, y) << " left border, row " << row;
          }
        }
        if (y + 1 < info.tilesY(level)) {
          Image below = *(*archive)->readTile({0, level, x, y + 1});
          for (uint32_t row = 0; row < b; ++row) {
            ASSERT_TRUE(std::equal(tile.row(b + t + row),
                                   tile.row(b + t + row) + tile.strideBytes(), below.row(b + row)))
                << tileName(level, x, y) << " bottom border, row " << row;
            ASSERT_TRUE(
                std::equal(below.row(row), below.row(row) + below.strideBytes(), tile.row(t + row)))
                << tileName(level, x, y + 1) << " top border, row " << row;
          }
        }
      }
    }
  }
}

TEST(Builder, SeveralInputsBecomeSeveralImages) {
  const std::string dir = test::testTempDir();
  Image gray = test::makePatternImage(90, 70, 1, 1);
  ASSERT_EQ(test::writeImagePng(dir + "a.png", gray), "");
  BuildOptions options;
  options.inputs = {dir + "a.png", "synthetic:130x100:5:4"};
  options.image_names = {"first"};
  options.output = dir + "set.tess";
  options.tile_size_px = 64;
  options.codec = Codec::kZstd;
  options.threads = 2;
  auto report = buildArchive(options);
  ASSERT_TRUE(report) << report.error().message;
  auto archive = Archive::openFile(options.output);
  ASSERT_TRUE(archive);
  ASSERT_EQ((*archive)->images().size(), 2u);
  EXPECT_EQ((*archive)->images()[0].name, "first");
  EXPECT_EQ((*archive)->images()[1].name, "synthetic:130x100:5:4");
  EXPECT_EQ((*archive)->images()[1].channels, 4u);
  test::ReferencePyramid second(test::readSource("synthetic:130x100:5:4"));
  auto region = (*archive)->readRegion(1, 1, {0, 0, 65, 50});
  ASSERT_TRUE(region);
  EXPECT_EQ(test::firstDifference(second.level(1), *region), "");
  EXPECT_TRUE((*archive)->verify().ok());
}

// ---- Bad inputs ------------------------------------------------------------------------------

struct BadInputResult {
  Error error;
  std::vector<std::string> out_dir_listing;
};

// Builds `input` into a fresh, empty output directory; the build must fail.
BadInputResult buildMustFail(const std::string& input, const std::string& out_dir) {
  std::filesystem::create_directories(out_dir);
  BuildOptions options;
  options.inputs = {input};
  options.output = out_dir + "/out.tess";
  options.codec = Codec::kZstd;
  options.threads = 2;
  auto report = buildArchive(options);
  BadInputResult result;
  EXPECT_FALSE(report) << input << " built";
  if (!report) result.error = report.error();
  result.out_dir_listing = listDir(out_dir);
  return result;
}

std::vector<uint8_t> fixtureBytes(const std::string& kind, const std::string& path) {
  std::vector<uint8_t> pixels = test::makeTestPixels(120, 90, 3, 4);
  std::string error;
  if (kind == "png") {
    test::PngSpec spec;
    spec.width_px = 120;
    spec.height_px = 90;
    error = test::writePng(path, spec, pixels);
  } else if (kind == "tiff") {
    test::TiffSpec spec;
    spec.width_px = 120;
    spec.height_px = 90;
    spec.compression = 8;  // deflate, so damaged strips are detectable
    error = test::writeTiff(path, spec, pixels);
  } else {
    test::JpegSpec spec;
    spec.width_px = 120;
    spec.height_px = 90;
    error = test::writeJpeg(path, spec, pixels);
  }
  EXPECT_EQ(error, "");
  return test::readFileBytes(path);
}

// ---- ptm: tiles coded against their parent -------------------------------------------------

TEST(BuilderPtm, EveryLevelDecodesToTheFloorAveragePyramidForOddSizesAndAllChannels) {
  const std::string dir = test::testTempDir();
  struct Case {
    uint32_t width, height, channels, border;
  };
  for (const Case& c :
       {Case{333, 201, 1, 0}, Case{257, 190, 2, 1}, Case{300, 129, 3, 3}, Case{129, 260, 4, 2}}) {
    // The synthetic source makes RGB and RGBA; gray and gray+alpha come from it through PNG.
    const std::string synthetic = "synthetic:" + std::to_string(c.width) + "x" +
                                  std::to_string(c.height) +
                                  ":5:" + std::to_string(c.channels == 2 ? 4 : 3);
    std::string source = synthetic;
    if (c.channels <= 2) {
      Image rgb = test::readSource(synthetic);
      const uint32_t from = rgb.channels;
      std::vector<uint8_t> pixels;
      for (size_t i = 0; i < size_t(c.width) * c.height; ++i) {
        pixels.push_back(rgb.texels[i * from]);
        if (c.channels == 2) pixels.push_back(rgb.texels[i * from + 3]);
      }
      source = dir + "gray" + std::to_string(c.channels) + ".png";
      test::PngSpec spec{.width_px = c.width, .height_px = c.height};
      spec.colour = c.channels == 1 ? test::PngColour::kGray : test::PngColour::kGrayAlpha;
      ASSERT_EQ(test::writePng(source, spec, pixels), "");
    }
    BuildOptions options;
    options.inputs = {source};
    options.output = dir + "ptm.tess";
    options.codec = Codec::kPtm;
    options.tile_size_px = 64;
    options.border_px = c.border;
    options.threads = 2;
    auto report = buildArchive(options);
    ASSERT_TRUE(report) << report.error().message;
    EXPECT_GT(report->tiles_encoded, 0u);
    auto archive = Archive::openFile(options.output);
    ASSERT_TRUE(archive) << archive.error().message;
    EXPECT_EQ(nlohmann::json::parse((*archive)->metadataJson())["build"]["downsample"],
              "box-floor");
    test::ReferencePyramid reference(test::readSource(source), /*floor_average=*/true);
    expectArchiveEqualsReference(**archive, reference);
    VerifyReport verified = (*archive)->verify();
    EXPECT_TRUE(verified.ok()) << (verified.faults.empty() ? "" : verified.faults[0]);
    EXPECT_EQ(verified.payloads_checked, report->tiles_encoded);
  }
}

TEST(BuilderPtm, OtherCodecsKeepTheRoundedPyramid) {
  const std::string dir = test::testTempDir();
  BuildOptions options;
  options.inputs = {"synthetic:150x150:2:3"};
  options.output = dir + "zstd.tess";
  options.codec = Codec::kZstd;
  options.tile_size_px = 64;
  ASSERT_TRUE(buildArchive(options));
  auto archive = Archive::openFile(options.output);
  ASSERT_TRUE(archive);
  test::ReferencePyramid rounded(test::readSource("synthetic:150x150:2:3"));
  expectArchiveEqualsReference(**archive, rounded);
}

// Corrupts one byte in the middle of `tile`'s payload in the archive file.
void corruptPayload(const std::string& path, const TileId& tile) {
  auto archive = Archive::openFile(path);
  ASSERT_TRUE(archive);
  auto entry = (*archive)->tileEntry(tile);
  ASSERT_TRUE(entry);
  ASSERT_EQ(entry->kind, TileKind::kEncoded);
  std::vector<uint8_t> bytes = test::readFileBytes(path);
  bytes[entry->offset_bytes + entry->length_bytes / 2] ^= 0x20;
  ASSERT_TRUE(test::writeFileBytes(path, bytes));
}

TEST(BuilderPtm, ACorruptParentOrResidualFailsTheTileNamingItAndNeverYieldsPixels) {
  const std::string dir = test::testTempDir();
  BuildOptions options;
  options.inputs = {"synthetic:500x400:9:3"};
  options.output = dir + "good.tess";
  options.codec = Codec::kPtm;
  options.tile_size_px = 64;
  options.border_px = 1;
  ASSERT_TRUE(buildArchive(options));
  const std::vector<uint8_t> good = test::readFileBytes(options.output);
  const std::string path = dir + "bad.tess";

  // A corrupt parent (level 1) fails its four children and their descendants, naming it.
  ASSERT_TRUE(test::writeFileBytes(path, good));
  corruptPayload(path, {0, 1, 1, 1});
  auto archive = Archive::openFile(path);
  ASSERT_TRUE(archive);
  int encoded_children = 0;
  for (uint32_t y = 2; y < 4; ++y)
    for (uint32_t x = 2; x < 4; ++x) {
      auto entry = (*archive)->tileEntry({0, 0, x, y});
      ASSERT_TRUE(entry);
      if (entry->kind != TileKind::kEncoded) continue;  // uniform tiles need no parent
      ++encoded_children;
      auto child = (*archive)->readTile({0, 0, x, y});
      ASSERT_FALSE(child) << x << "," << y;
      EXPECT_NE(child.error().message.find("tile (1,1,1) checksum mismatch"), std::string::npos)
          << child.error().message;
      EXPECT_NE(child.error().message.find("parent"), std::string::npos);
    }
  EXPECT_GE(encoded_children, 2);
  EXPECT_TRUE((*archive)->readTile({0, 0, 0, 0}));  // another parent's child is unaffected
  VerifyReport report = (*archive)->verify();
  EXPECT_FALSE(report.ok());
  // The parent's checksum and each encoded child.
  EXPECT_EQ(report.fault_count, 1u + encoded_children);
  EXPECT_FALSE((*archive)->readRegion(0, 0, {128, 128, 128, 128}));

  // A corrupt residual payload fails that tile only.
  ASSERT_TRUE(test::writeFileBytes(path, good));
  corruptPayload(path, {0, 0, 3, 2});
  archive = Archive::openFile(path);
  ASSERT_TRUE(archive);
  auto tile = (*archive)->readTile({0, 0, 3, 2});
  ASSERT_FALSE(tile);
  EXPECT_NE(tile.error().message.find("tile (0,3,2) checksum mismatch"), std::string::npos);
  EXPECT_TRUE((*archive)->readTile({0, 0, 2, 2}));
  EXPECT_EQ((*archive)->verify().fault_count, 1u);
}

TEST(BuilderPtm, DecodingWithACallerSuppliedParentEqualsReadTile) {
  const std::string dir = test::testTempDir();
  BuildOptions options;
  options.inputs = {"synthetic:200x200:4:4"};
  options.output = dir + "ptm.tess";
  options.codec = Codec::kPtm;
  options.tile_size_px = 64;
  ASSERT_TRUE(buildArchive(options));
  auto archive = Archive::openFile(options.output);
  ASSERT_TRUE(archive);
  const TileId tile{0, 0, 3, 1};
  auto parent = (*archive)->readTile(Archive::parentTile(tile));
  ASSERT_TRUE(parent);
  auto entry = (*archive)->tileEntry(tile);
  ASSERT_TRUE(entry);
  ASSERT_EQ(entry->kind, TileKind::kEncoded);
  auto payload = (*archive)->readPayload(tile, *entry);
  ASSERT_TRUE(payload);
  Image out;
  ASSERT_TRUE((*archive)->decodeTileInto(tile, *entry, *payload, out, *parent));
  auto expected = (*archive)->readTile(tile);
  ASSERT_TRUE(expected);
  EXPECT_EQ(out.texels, expected->texels);
  Image wrong_size(8, 8, 4);
  EXPECT_FALSE((*archive)->decodeTileInto(tile, *entry, *payload, out, wrong_size));
}

TEST(BuilderBadInput, EachFailsNamingTheFileAndLeavesNoOutput) {
  const std::string dir = test::testTempDir();
  struct Bad {
    std::string name;
    std::vector<uint8_t> bytes;
    bool write = true;
  };
  std::vector<Bad> cases;
  cases.push_back({"missing.png", {}, false});
  cases.push_back({"empty.png", {}});
  for (const std::string kind : {"png", "tiff", "jpeg"}) {
    std::vector<uint8_t> good = fixtureBytes(kind, dir + "good." + kind);
    ASSERT_GT(good.size(), 200u);
    cases.push_back({"truncated_header." + kind, {good.begin(), good.begin() + 20}});
    cases.push_back({"truncated." + kind, {good.begin(), good.begin() + good.size() * 6 / 10}});
    std::vector<uint8_t> corrupt = good;
    for (size_t i = corrupt.size() / 3; i < corrupt.size() * 2 / 3; ++i)
      corrupt[i] = uint8_t(i * 151);
    cases.push_back({"corrupt." + kind, corrupt});
  }
  cases.push_back({"zero_width.tif", test::makeRawTiffHeader(0, 10, 16)});
  cases.push_back({"zero_height.tif", test::makeRawTiffHeader(10, 0, 16)});
  cases.push_back({"zero.png", test::makePngHeaderOnly(0, 0)});
  cases.push_back({"absurd.tif", test::makeRawTiffHeader(4000000000u, 4000000000u, 16)});
  cases.push_back({"absurd.png", test::makePngHeaderOnly(4000000000u, 4000000000u)});
  cases.push_back({"wide.png", test::makePngHeaderOnly(kMaxImageSidePx + 1, 1)});
  cases.push_back({"text.png", {'h', 'e', 'l', 'l', 'o', '\n'}});
  for (const Bad& bad : cases) {
    SCOPED_TRACE(bad.name);
    const std::string path = dir + "in/" + bad.name;
    std::filesystem::create_directories(dir + "in");
    if (bad.write) {
      ASSERT_TRUE(test::writeFileBytes(path, bad.bytes));
    }
    BadInputResult result = buildMustFail(path, dir + "out_" + bad.name);
    EXPECT_NE(result.error.message.find(path), std::string::npos) << result.error.message;
    EXPECT_TRUE(result.out_dir_listing.empty());
  }
}

// 16-bit and 32-bit float sources build (sample_type_build_test.cpp); other depths and
// signed samples are refused naming the file and the depth.
TEST(BuilderBadInput, UnsupportedSampleFormatsAreNamed) {
  const std::string dir = test::testTempDir();
  std::vector<uint8_t> pixels = test::makeTestPixels(40, 30, 3, 2);
  test::TiffSpec tiff32;
  tiff32.width_px = 40;
  tiff32.height_px = 30;
  tiff32.bits = 32;
  ASSERT_EQ(test::writeTiff(dir + "deep.tif", tiff32, pixels), "");
  test::TiffSpec tiff_signed = tiff32;
  tiff_signed.bits = 16;
  tiff_signed.sample_format = 2;  // SAMPLEFORMAT_INT
  ASSERT_EQ(test::writeTiff(dir + "signed.tif", tiff_signed, pixels), "");
  const std::pair<const char*, const char*> cases[] = {{"deep.tif", "32-bit"},
                                                       {"signed.tif", "signed"}};
  for (const auto& [name, word] : cases) {
    SCOPED_TRACE(name);
    BadInputResult result = buildMustFail(dir + name, dir + "out_" + name);
    EXPECT_EQ(result.error.code, ErrorCode::kUnsupported);
    EXPECT_NE(result.error.message.find(dir + name), std::string::npos) << result.error.message;
    EXPECT_NE(result.error.message.find(word), std::string::npos) << result.error.message;
    EXPECT_TRUE(result.out_dir_listing.empty());
  }
}

TEST(BuilderBadInput, InvalidOptionsAreRejectedBeforeAnyOutput) {
  const std::string dir = test::testTempDir();
  auto base = [&] {
    BuildOptions options;
    options.inputs = {"synthetic:100x100"};
    options.output = dir + "out.tess";
    options.codec = Codec::kZstd;
    return options;
  };
  std::vector<BuildOptions> bad(8, base());
  bad[0].tile_size_px = 100;
  bad[1].tile_size_px = 32;
  bad[2].tile_size_px = 4096;
  bad[3].border_px = 17;
  bad[4].quality = 0;
  bad[5].inputs.clear();
  bad[6].output.clear();
  bad[7].codec = Codec::kPtm;  // the floor-average pyramid cannot be averaged in linear light
  bad[7].srgb_downsample = true;
  for (size_t i = 0; i < bad.size(); ++i) {
    auto report = buildArchive(bad[i]);
    EXPECT_FALSE(report) << i;
  }
  BuildOptions same = base();
  ASSERT_TRUE(test::writeFileBytes(dir + "in.png", {1}));
  same.inputs = {dir + "in.png"};
  same.output = dir + "./in.png";
  auto report = buildArchive(same);
  ASSERT_FALSE(report);
  EXPECT_EQ(test::readFileBytes(dir + "in.png"), std::vector<uint8_t>{1});
  EXPECT_EQ(listDir(dir), std::vector<std::string>{"in.png"});
}

// ---- Failing outputs -------------------------------------------------------------------------

TEST(BuilderOutput, AnOutputUnderARegularFileFailsNamingIt) {
  const std::string dir = test::testTempDir();
  ASSERT_TRUE(test::writeFileBytes(dir + "file", {1, 2, 3}));
  BuildOptions options;
  options.inputs = {"synthetic:100x80"};
  options.output = dir + "file/out.tess";
  auto report = buildArchive(options);
  ASSERT_FALSE(report);
  EXPECT_NE(report.error().message.find(options.output), std::string::npos)
      << report.error().message;
  EXPECT_EQ(listDir(dir), std::vector<std::string>{"file"});
}

TEST(BuilderOutput, AnUnwritableDirectoryFailsNamingIt) {
  std::string dir = test::testTempDir();
  std::string out_dir;
  if (::geteuid() == 0) {
    // Permission bits do not stop root; /proc refuses new files whoever asks.
    out_dir = "/proc";
  } else {
    out_dir = dir + "readonly";
    std::filesystem::create_directories(out_dir);
    ASSERT_EQ(::chmod(out_dir.c_str(), 0555), 0);
  }
  BuildOptions options;
  options.inputs = {"synthetic:100x80"};
  options.output = out_dir + "/out.tess";
  auto report = buildArchive(options);
  ASSERT_FALSE(report);
  EXPECT_NE(report.error().message.find(options.output), std::string::npos)
      << report.error().message;
  EXPECT_FALSE(std::filesystem::exists(options.output));
  if (::geteuid() != 0) {
    EXPECT_TRUE(listDir(out_dir).empty());
    ::chmod(out_dir.c_str(), 0755);
  }
}

TEST(BuilderOutput, ADiskFullFailsCleanly) {
  const std::string root = test::testTempDir();
  const std::string dir = root + "small";
  std::filesystem::create_directories(dir);
  // Noise zstd cannot shrink: 1.4 MiB of payloads where the free-space check, which assumes
  // zstd saves 70 %, expects 0.9 MiB for spool and archive together; so the disk fills mid-way.
  std::vector<uint8_t> noise(600 * 600 * 3);
  std::mt19937 random(7);
  for (uint8_t& byte : noise) byte = uint8_t(random());
  test::TiffSpec spec;
  spec.width_px = spec.height_px = 600;
  ASSERT_EQ(test::writeTiff(root + "noise.tif", spec, noise), "");
  if (::mount("tmpfs", dir.c_str(), "tmpfs", 0, "size=1m") != 0)
    GTEST_SKIP() << "cannot mount a 1 MiB tmpfs at " << dir
                 << " (needs root): " << std::strerror(errno);
  ASSERT_TRUE(test::writeFileBytes(dir + "/previous.tess", std::vector<uint8_t>(1000, 'p')));
  BuildOptions options;
  options.inputs = {root + "noise.tif"};
  options.output = dir + "/previous.tess";
  options.codec = Codec::kZstd;
  options.threads = 2;
  auto report = buildArchive(options);
  std::vector<std::string> listing = listDir(dir);
  std::vector<uint8_t> previous = test::readFileBytes(dir + "/previous.tess");
  ::umount(dir.c_str());
  ASSERT_FALSE(report);
  EXPECT_EQ(report.error().code, ErrorCode::kIo);
  EXPECT_NE(report.error().message.find(options.output), std::string::npos)
      << report.error().message;
  EXPECT_NE(report.error().message.find(std::strerror(ENOSPC)), std::string::npos)
      << report.error().message;
  EXPECT_EQ(listing, std::vector<std::string>{"previous.tess"});
  EXPECT_EQ(previous, std::vector<uint8_t>(1000, 'p'));
}

TEST(BuilderOutput, ABuildThatCannotFitIsRefusedBeforeItStarts) {
  const std::string root = test::testTempDir();
  const std::string dir = root + "small";
  std::filesystem::create_directories(dir);
  std::filesystem::create_directories(root + "spool");
  if (::mount("tmpfs", dir.c_str(), "tmpfs", 0, "size=1m") != 0)
    GTEST_SKIP() << "cannot mount a 1 MiB tmpfs at " << dir
                 << " (needs root): " << std::strerror(errno);
  BuildOptions options;
  options.inputs = {"synthetic:1024x1024:2:4"};  // 5.3 MiB of raw RGBA pyramid, twice
  options.output = dir + "/out.tess";
  options.codec = Codec::kRaw;
  auto report = buildArchive(options);
  std::vector<std::string> listing = listDir(dir);
  // The spool elsewhere: the archive alone still does not fit.
  options.spool_dir = root + "spool";
  auto spooled_elsewhere = buildArchive(options);
  ::umount(dir.c_str());
  ASSERT_FALSE(report);
  EXPECT_EQ(report.error().code, ErrorCode::kIo);
  const std::string& message = report.error().message;
  EXPECT_NE(message.find(options.output), std::string::npos) << message;
  EXPECT_NE(message.find("10.7 MiB free in " + dir), std::string::npos) << message;
  EXPECT_NE(message.find("--spool-dir"), std::string::npos) << message;
  EXPECT_TRUE(listing.empty());
  ASSERT_FALSE(spooled_elsewhere);
  EXPECT_NE(spooled_elsewhere.error().message.find("archive's bytes need at least 5.3 MiB"),
            std::string::npos)
      << spooled_elsewhere.error().message;
}

// ---- Cancellation and previous files ---------------------------------------------------------

TEST(BuilderCancel, ACancelledBuildLeavesNoFile) {
  const std::string dir = test::testTempDir();
  std::atomic<bool> cancel{true};
  BuildOptions options;
  options.inputs = {"synthetic:500x500"};
  options.output = dir + "out.tess";
  auto report = buildArchive(options, {}, &cancel);
  ASSERT_FALSE(report);
  EXPECT_EQ(report.error().code, ErrorCode::kCancelled);
  EXPECT_NE(report.error().message.find(options.output), std::string::npos);
  EXPECT_TRUE(listDir(dir).empty());
}

TEST(BuilderCancel, CancellingMidBuildKeepsThePreviousFile) {
  const std::string dir = test::testTempDir();
  const std::vector<uint8_t> previous(777, 'p');
  ASSERT_TRUE(test::writeFileBytes(dir + "out.tess", previous));
  std::atomic<bool> cancel{false};
  uint64_t progress_calls = 0, pixels_at_cancel = 0, pixels_total = 0;
  BuildOptions options;
  // Far more work than one 100 ms progress interval, so the callback runs mid-build.
  options.inputs = {"synthetic:16384x16384"};
  options.output = dir + "out.tess";
  options.codec = Codec::kLz4;
  options.threads = 2;
  auto report = buildArchive(
      options,
      [&](const BuildProgress& progress) {
        ++progress_calls;
        if (!cancel) pixels_at_cancel = progress.pixels_done, pixels_total = progress.pixels_total;
        cancel = true;
      },
      &cancel);
  ASSERT_FALSE(report);
  EXPECT_EQ(report.error().code, ErrorCode::kCancelled);
  EXPECT_GE(progress_calls, 1u);
  EXPECT_LT(pixels_at_cancel, pixels_total);
  EXPECT_EQ(test::readFileBytes(dir + "out.tess"), previous);
  EXPECT_EQ(listDir(dir), std::vector<std::string>{"out.tess"});
}

TEST(BuilderCancel, AFailedBuildKeepsThePreviousFileAndASuccessfulOneReplacesIt) {
  const std::string dir = test::testTempDir();
  const std::vector<uint8_t> previous(123, 'q');
  ASSERT_TRUE(test::writeFileBytes(dir + "out.tess", previous));
  ASSERT_TRUE(test::writeFileBytes(dir + "bad.png", {0x89, 'P', 'N', 'G'}));
  BuildOptions options;
  options.inputs = {dir + "bad.png"};
  options.output = dir + "out.tess";
  EXPECT_FALSE(buildArchive(options));
  EXPECT_EQ(test::readFileBytes(dir + "out.tess"), previous);
  options.inputs = {"synthetic:100x100"};
  options.codec = Codec::kZstd;
  ASSERT_TRUE(buildArchive(options));
  EXPECT_TRUE(Archive::openFile(dir + "out.tess"));
  EXPECT_EQ(listDir(dir), (std::vector<std::string>{"bad.png", "out.tess"}));
}

TEST(Builder, ReportsProgressEndingAtTheTotal) {
  const std::string dir = test::testTempDir();
  BuildOptions options;
  options.inputs = {"synthetic:300x200"};
  options.output = dir + "out.tess";
  options.codec = Codec::kZstd;
  std::vector<BuildProgress> calls;
  auto report = buildArchive(options, [&](const BuildProgress& p) { calls.push_back(p); });
  ASSERT_TRUE(report);
  ASSERT_FALSE(calls.empty());
  EXPECT_EQ(calls.back().pixels_done, 300u * 200);
  EXPECT_EQ(calls.back().pixels_total, 300u * 200);
  for (size_t i = 1; i < calls.size(); ++i)
    EXPECT_GE(calls[i].pixels_done, calls[i - 1].pixels_done);
}

}  // namespace
}  // namespace tessera
