// Mosaic manifests read as one image: a build from a manifest has the pixels of the mosaic
// assembled in memory (later images over earlier ones, background in the gaps), bands open
// only the images they cross, a part of a split build reads only its images, the parts merge
// into the single build, and bad images are refused naming the manifest and the entry.
#include <filesystem>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <tessera/archive.h>
#include <tessera/build.h>
#include <tessera/split_build.h>

#include "builder/band_reader.h"
#include "builder/mosaic_reader.h"
#include "support/test_images.h"

namespace tessera {
namespace {

/// One image of a test mosaic: where it goes and how it is stored.
struct Placed {
  uint32_t x = 0, y = 0, width = 0, height = 0;
  bool tiff = false;  ///< uncompressed tiled TIFF (32 px tiles), else PNG
};

/// Image `i`'s pixel at its own (x, y): differs between neighbours and between images.
uint8_t texel(size_t i, uint32_t x, uint32_t y, uint32_t c) {
  return uint8_t((x * 7 + y * 13 + c * 91 + i * 59 + (x * y) / 5) & 0xff);
}

std::vector<uint8_t> imagePixels(size_t i, const Placed& image) {
  std::vector<uint8_t> pixels;
  for (uint32_t y = 0; y < image.height; ++y)
    for (uint32_t x = 0; x < image.width; ++x)
      for (uint32_t c = 0; c < 3; ++c) pixels.push_back(texel(i, x, y, c));
  return pixels;
}

/// Stored bytes of image `image` as writeMosaic writes a TIFF: whole 32 px RGB tiles.
uint64_t storedBytes(const Placed& image) {
  return uint64_t((image.width + 31) / 32) * ((image.height + 31) / 32) * 32 * 32 * 3;
}

/// Writes the images (img-I.png or .tif) and `dir`/mosaic.json placing them on a canvas of
/// `width` x `height` with a background of (10, 20, 30). Returns the manifest's path.
std::string writeMosaic(const std::string& dir, const std::vector<Placed>& images, uint32_t width,
                        uint32_t height) {
  nlohmann::json entries = nlohmann::json::array();
  for (size_t i = 0; i < images.size(); ++i) {
    const Placed& image = images[i];
    const std::string name = fmt::format("img-{}.{}", i, image.tiff ? "tif" : "png");
    if (image.tiff) {
      test::TiffSpec spec;
      spec.width_px = image.width;
      spec.height_px = image.height;
      spec.tiled = true;
      spec.tile_width_px = spec.tile_height_px = 32;
      EXPECT_EQ(test::writeTiff(dir + name, spec, imagePixels(i, image)), "");
    } else {
      test::PngSpec spec;
      spec.width_px = image.width;
      spec.height_px = image.height;
      EXPECT_EQ(test::writePng(dir + name, spec, imagePixels(i, image)), "");
    }
    entries.push_back({{"path", name}, {"x", image.x}, {"y", image.y}});
  }
  nlohmann::json manifest = {
      {"width", width}, {"height", height}, {"background", {10, 20, 30}}, {"images", entries}};
  const std::string text = manifest.dump(2);
  EXPECT_TRUE(test::writeFileBytes(dir + "mosaic.json", {text.begin(), text.end()}));
  return dir + "mosaic.json";
}

/// The same mosaic assembled in memory: background, then each image over the ones before.
std::vector<uint8_t> assemble(const std::vector<Placed>& images, uint32_t width, uint32_t height) {
  std::vector<uint8_t> canvas;
  for (uint32_t i = 0; i < width * height; ++i) canvas.insert(canvas.end(), {10, 20, 30});
  for (size_t i = 0; i < images.size(); ++i)
    for (uint32_t y = 0; y < images[i].height; ++y)
      for (uint32_t x = 0; x < images[i].width; ++x)
        for (uint32_t c = 0; c < 3; ++c)
          canvas[((images[i].y + y) * width + images[i].x + x) * 3 + c] = texel(i, x, y, c);
  return canvas;
}

BuildOptions options(const std::string& input, const std::string& output) {
  BuildOptions build;
  build.inputs = {input};
  build.output = output;
  build.tile_size_px = 64;
  build.border_px = 1;
  build.codec = Codec::kZstd;  // lossless: the tiles compare texel for texel
  build.threads = 2;
  return build;
}

// Overlaps (image 2 over 0 and 1, image 3 inside 2), gaps at the right and bottom, PNG and
// tiled TIFF images of different sizes.
const std::vector<Placed> kScattered = {
    {0, 0, 70, 90, false}, {90, 10, 60, 50, true}, {40, 40, 80, 70, true}, {60, 60, 20, 20, false}};
constexpr uint32_t kCanvasWidth = 170, kCanvasHeight = 130;

TEST(MosaicReader, BuildsThePixelsOfTheMosaicAssembledInMemory) {
  const std::string dir = test::testTempDir();
  const std::string manifest = writeMosaic(dir, kScattered, kCanvasWidth, kCanvasHeight);
  test::PngSpec spec;
  spec.width_px = kCanvasWidth;
  spec.height_px = kCanvasHeight;
  ASSERT_EQ(
      test::writePng(dir + "whole.png", spec, assemble(kScattered, kCanvasWidth, kCanvasHeight)),
      "");
  auto built = buildArchive(options(manifest, dir + "mosaic.tess"));
  ASSERT_TRUE(built) << built.error().message;
  ASSERT_TRUE(buildArchive(options(dir + "whole.png", dir + "whole.tess")));
  auto mosaic = Archive::openFile(dir + "mosaic.tess");
  auto whole = Archive::openFile(dir + "whole.tess");
  ASSERT_TRUE(mosaic && whole);
  const ImageInfo& info = (*mosaic)->images()[0];
  ASSERT_EQ(info.width_px, kCanvasWidth);
  ASSERT_EQ(info.height_px, kCanvasHeight);
  for (uint32_t l = 0; l < info.level_count; ++l) {
    for (uint32_t y = 0; y < info.tilesY(l); ++y) {
      for (uint32_t x = 0; x < info.tilesX(l); ++x) {
        auto a = (*mosaic)->readTile({0, l, x, y});
        auto b = (*whole)->readTile({0, l, x, y});
        ASSERT_TRUE(a && b);
        EXPECT_TRUE(a->texels == b->texels) << "level " << l << " tile " << x << "," << y;
      }
    }
  }
}

TEST(MosaicReader, CanvasDefaultsToTheImagesExtent) {
  const std::string dir = test::testTempDir();
  writeMosaic(dir, kScattered, kCanvasWidth, kCanvasHeight);
  const std::string text =
      R"({"images": [{"path": "img-0.png", "x": 5, "y": 0}, {"path": "img-1.tif", "x": 0,
          "y": 100, "width": 60, "height": 50}]})";
  ASSERT_TRUE(test::writeFileBytes(dir + "extent.json", {text.begin(), text.end()}));
  auto reader = detail::openBandReader(dir + "extent.json");
  ASSERT_TRUE(reader) << reader.error().message;
  EXPECT_EQ((*reader)->info().width_px, 75u);
  EXPECT_EQ((*reader)->info().height_px, 150u);
  EXPECT_EQ((*reader)->info().format, "mosaic");
  std::string error;
  const std::vector<uint8_t> rows = test::readAllRows(**reader, 16, &error);
  ASSERT_EQ(error, "");
  EXPECT_EQ(rows[0], 0);                          // (0, 0): no background given, zeros
  EXPECT_EQ(rows[5 * 3 + 1], texel(0, 0, 0, 1));  // image 0's corner
  EXPECT_EQ(rows[(120 * 75 + 59) * 3 + 2], texel(1, 59, 20, 2));
}

TEST(MosaicReader, OpensOnlyTheImagesABandCrosses) {
  const std::string dir = test::testTempDir();
  // Two bands of images: rows 0..63 and 64..127, each image an uncompressed tiled TIFF.
  const std::vector<Placed> images = {
      {0, 0, 64, 64, true}, {64, 0, 64, 64, true}, {0, 64, 128, 64, true}};
  const std::string manifest = writeMosaic(dir, images, 128, 128);
  auto reader = detail::openMosaicReader(manifest);
  ASSERT_TRUE(reader) << reader.error().message;
  const size_t row_bytes = 128 * 3;
  // With the lower image gone, the upper band still reads: it was never opened.
  std::filesystem::rename(dir + "img-2.tif", dir + "aside.tif");
  std::vector<uint8_t> rows(33 * row_bytes);
  ASSERT_TRUE((*reader)->readRows(32, rows));
  EXPECT_EQ(rows[(31 * 128 + 100) * 3], texel(1, 36, 31, 0));
  // One 32-row tile row of each upper image, nothing of the lower one.
  EXPECT_EQ((*reader)->storedBytesRead(), 2u * 32 * 32 * 3 * 2);
  auto failed = (*reader)->readRows(33, rows);
  ASSERT_FALSE(failed);
  EXPECT_NE(failed.error().message.find(manifest + ": images[2]: " + dir + "img-2.tif"),
            std::string::npos)
      << failed.error().message;

  // Skipping past the upper images opens neither, and the lower one reads only what it needs.
  std::filesystem::rename(dir + "aside.tif", dir + "img-2.tif");
  reader = detail::openMosaicReader(manifest);
  ASSERT_TRUE(reader) << reader.error().message;
  std::filesystem::remove(dir + "img-0.tif");
  std::filesystem::remove(dir + "img-1.tif");
  ASSERT_TRUE((*reader)->skipRows(96));
  ASSERT_TRUE((*reader)->readRows(32, rows));
  EXPECT_EQ(rows[(5 * 128 + 77) * 3 + 2], texel(2, 77, 37, 2));
  EXPECT_EQ((*reader)->storedBytesRead(), storedBytes(images[2]) / 2);
}

TEST(MosaicReader, RefusesBadImagesNamingTheManifestAndEntry) {
  const std::string dir = test::testTempDir();
  writeMosaic(dir, kScattered, kCanvasWidth, kCanvasHeight);
  test::PngSpec gray;
  gray.width_px = gray.height_px = 8;
  gray.colour = test::PngColour::kGray;
  ASSERT_EQ(test::writePng(dir + "gray.png", gray, std::vector<uint8_t>(64, 7)), "");
  const std::string manifest = dir + "bad.json";
  auto refusal = [&](const std::string& text) {
    EXPECT_TRUE(test::writeFileBytes(manifest, {text.begin(), text.end()}));
    auto result = buildArchive(options(manifest, dir + "out.tess"));
    EXPECT_FALSE(std::filesystem::exists(dir + "out.tess"));
    return result ? std::string("built") : result.error().message;
  };
  const std::string first = R"({"path": "img-0.png", "x": 0, "y": 0}, )";
  struct Case {
    std::string images, background, expected;
  };
  const std::vector<Case> cases = {
      {R"({"path": "none.png", "x": 0, "y": 0})", "",
       "bad.json: images[1]: " + dir + "none.png: no such file"},
      {R"({"path": "img-1.tif", "x": 150, "y": 0})", "",
       "images[1] (img-1.tif): 60x50 px at (150, 0) reaches past the canvas of 170x130 px"},
      {R"({"path": "img-1.tif", "x": 0, "y": 0, "height": 51})", "",
       "images[1] (img-1.tif): the manifest states a height of 51 px, the file is 60x50 px"},
      {R"({"path": "gray.png", "x": 0, "y": 0})", "",
       "images[1] (gray.png): 1 channel(s) of u8 samples; a mosaic's images must all match"},
      {R"({"path": "bad.json", "x": 0, "y": 0})", "",
       "images[1]: " + manifest + ": a mosaic manifest, not an image"},
      {R"({"path": "img-3.png", "x": 0, "y": 0})", R"("background": [1, 2],)",
       "bad.json: \"background\" has 2 value(s), the images 3 channel(s)"},
      {R"({"path": "img-3.png", "x": 0, "y": 0})", R"("background": [1, 2, 256],)",
       "\"background\" value 256 is not a whole number 0..255 for u8 samples"}};
  for (const Case& c : cases) {
    const std::string message = refusal(fmt::format(
        R"({{"width": 170, "height": 130, {} "images": [{}{}]}})", c.background, first, c.images));
    EXPECT_NE(message.find(c.expected), std::string::npos) << message;
  }
}

TEST(MosaicReader, SplitPartsReadOnlyTheirImagesAndMergeIntoTheSingleBuild) {
  const std::string dir = test::testTempDir();
  // A tall strip of four images, each overlapping the one above by 8 rows.
  std::vector<Placed> images;
  for (uint32_t i = 0; i < 4; ++i) images.push_back({i * 5, i * 120, 100, 128, true});
  const uint32_t height = 3 * 120 + 128;
  const std::string manifest = writeMosaic(dir, images, 120, height);
  const BuildOptions single = options(manifest, dir + "single.tess");
  ASSERT_TRUE(buildArchive(single));
  std::vector<std::string> parts;
  uint64_t read_by_all = 0, stored_by_all = 0;
  for (const Placed& image : images) stored_by_all += storedBytes(image);
  for (uint32_t i = 1; i <= 4; ++i) {
    BuildOptions part = single;
    part.output = fmt::format("{}part-{}.tess", dir, i);
    auto built = buildArchivePart(part, {i, 4});
    ASSERT_TRUE(built) << built.error().message;
    parts.push_back(part.output);
    auto archive = Archive::openFile(part.output);
    ASSERT_TRUE(archive);
    const auto meta = nlohmann::json::parse((*archive)->metadataJson())["split_part"];
    // The part reads its rows and a band either side (borders): no image outside that.
    const uint32_t band = 64u << (meta["merge_level"].get<uint32_t>() - 1);
    const uint32_t first = meta["rows"][0].get<uint32_t>(), end = meta["rows"][1].get<uint32_t>();
    const uint32_t window_first = first > band ? first - band : 0;
    const uint32_t window_end = std::min(height, end + band);
    uint64_t crossed = 0;
    for (const Placed& image : images)
      if (image.y < window_end && image.y + image.height > window_first)
        crossed += storedBytes(image);
    const uint64_t read = meta["stored_bytes_read"].get<uint64_t>();
    EXPECT_LE(read, crossed) << "part " << i;
    if (end > first) {
      EXPECT_GT(read, 0u) << "part " << i;
    }
    read_by_all += read;
  }
  // Every image was read by some part, none whole by every part.
  EXPECT_GE(read_by_all, stored_by_all);
  EXPECT_LT(read_by_all, stored_by_all * 4);
  ASSERT_TRUE(mergeArchiveParts(parts, dir + "merged.tess"));
  EXPECT_TRUE(test::readFileBytes(dir + "single.tess") == test::readFileBytes(dir + "merged.tess"));
}

}  // namespace
}  // namespace tessera
