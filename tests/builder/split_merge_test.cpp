// Split builds (tessera/split_build.h): the merge of N parts is byte for byte the archive of a
// single build with the same options, over random sizes, part counts, tile sizes, borders,
// codecs and orders; missing, duplicate, foreign and damaged parts are refused naming the
// file, and leave no output.
#include <filesystem>
#include <fstream>
#include <optional>
#include <random>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <tessera/archive.h>
#include <tessera/split_build.h>

#include "format/tile_order.h"
#include "support/archive_fixture.h"
#include "support/test_images.h"

namespace tessera {
namespace {

BuildOptions syntheticOptions(const std::string& input, const std::string& output) {
  BuildOptions options;
  options.inputs = {input};
  options.output = output;
  options.tile_size_px = 64;
  options.threads = 2;
  return options;
}

/// Builds the N parts of `options` into `dir` and returns their paths.
std::vector<std::string> buildParts(BuildOptions options, uint32_t count, const std::string& dir) {
  std::vector<std::string> paths;
  for (uint32_t i = 1; i <= count; ++i) {
    options.output = fmt::format("{}/part-{}.tess", dir, i);
    Result<BuildReport> built = buildArchivePart(options, {i, count});
    EXPECT_TRUE(built) << built.error().message;
    paths.push_back(options.output);
  }
  return paths;
}

TEST(SplitMerge, MergeEqualsTheSingleBuild) {
  const std::string dir = test::testTempDir();
  std::mt19937 random(32);
  const Codec codecs[] = {Codec::kJpeg, Codec::kZstd, Codec::kPng,
                          Codec::kLz4,  Codec::kRaw,  Codec::kWebp};
  const TileOrder orders[] = {TileOrder::kHilbert, TileOrder::kQuadtree, TileOrder::kRowMajor};
  const uint32_t borders[] = {0, 1, 3, 16};
  for (int round = 0; round < 14; ++round) {
    const uint32_t width = 1 + random() % 900, height = 1 + random() % 900;
    const std::string input =
        fmt::format("synthetic:{}x{}:{}:{}", width, height, round, 3 + random() % 2);
    BuildOptions options = syntheticOptions(input, dir + "/single.tess");
    options.tile_size_px = random() % 3 == 0 ? 128 : 64;
    options.border_px = borders[random() % 4];
    options.codec = codecs[random() % 6];
    options.order = orders[random() % 3];
    options.srgb_downsample = random() % 4 == 0;
    options.quality = 50 + random() % 50;
    if (!validateBuildOptions(options)) options.codec = Codec::kJpeg;  // webp not built in
    const uint32_t parts = 1 + random() % 8;
    SCOPED_TRACE(fmt::format("{} tile {} border {} codec {} parts {}", input, options.tile_size_px,
                             options.border_px, codecName(options.codec), parts));
    Result<BuildReport> single = buildArchive(options);
    ASSERT_TRUE(single) << single.error().message;
    std::vector<std::string> paths = buildParts(options, parts, dir);
    std::reverse(paths.begin(), paths.end());  // any order
    Result<MergeReport> merged = mergeArchiveParts(paths, dir + "/merged.tess");
    ASSERT_TRUE(merged) << merged.error().message;
    EXPECT_TRUE(test::readFileBytes(dir + "/single.tess") ==
                test::readFileBytes(dir + "/merged.tess"));
    auto archive = Archive::openFile(dir + "/merged.tess");
    ASSERT_TRUE(archive) << archive.error().message;
    EXPECT_TRUE((*archive)->verify(/*decode=*/false).ok());
    for (const std::string& path : paths) std::filesystem::remove(path);
  }
}

// The merge reads each stretch of the output that one part holds in one call (the part stores
// its tiles in the output's order), runs of the writer's 1 MiB aside.
TEST(SplitMerge, ReadsEachStretchOfAPartInOneCall) {
  const std::string dir = test::testTempDir();
  for (TileOrder order : {TileOrder::kHilbert, TileOrder::kQuadtree, TileOrder::kRowMajor}) {
    BuildOptions options = syntheticOptions("synthetic:1200x1000:4:3", dir + "/unused.tess");
    options.codec = Codec::kZstd;
    options.order = order;
    const std::vector<std::string> paths = buildParts(options, 3, dir);
    Result<MergeReport> merged = mergeArchiveParts(paths, dir + "/merged.tess");
    ASSERT_TRUE(merged) << merged.error().message;

    std::vector<std::shared_ptr<Archive>> parts;
    for (const std::string& path : paths) {
      auto part = Archive::openFile(path);
      ASSERT_TRUE(part) << part.error().message;
      parts.push_back(*part);
    }
    const ImageInfo info = parts[0]->images()[0];
    uint64_t stretches = 0, tiles = 0, payload_bytes = 0;
    int previous = -1;
    for (const TileId& tile : detail::tileOrder(info, 0, order)) {
      int owner = -1;  // computed by the merge
      for (size_t p = 0; p < parts.size(); ++p) {
        Result<TileEntry> entry = parts[p]->tileEntry(tile);
        ASSERT_TRUE(entry);
        if (entry->kind != TileKind::kEncoded) continue;
        owner = int(p);
        ++tiles;
        payload_bytes += entry->length_bytes;
      }
      if (owner >= 0 && owner != previous) ++stretches;
      previous = owner;
    }
    SCOPED_TRACE(fmt::format("order {}", int(order)));
    EXPECT_EQ(merged->tiles_copied, tiles);
    // A run of the writer ends before a payload that would take it past 1 MiB.
    const uint64_t runs = 2 * payload_bytes / (1u << 20) + 1;
    EXPECT_GT(stretches, 0u);
    EXPECT_LE(merged->part_reads, stretches + runs);
    EXPECT_LT(merged->part_reads * 4, tiles);
    for (const std::string& path : paths) std::filesystem::remove(path);
  }
}

// A part of a tiled TIFF (classic and BigTIFF) or a striped one reads the tiles or strips of
// its own rows, not those above them, and the parts still merge into the single build.
TEST(SplitMerge, PartsOfATiffReadOnlyTheirRows) {
  const std::string dir = test::testTempDir();
  const uint32_t width = 512, height = 1024;
  std::vector<uint8_t> pixels(size_t(width) * height * 3);
  for (size_t i = 0; i < pixels.size(); ++i) pixels[i] = uint8_t((i * 7 + i / 1531) & 0xff);
  for (int layout : {0, 1, 2}) {  // tiled, tiled BigTIFF, striped
    const bool bigtiff = layout == 1;
    test::TiffSpec spec;
    spec.width_px = width;
    spec.height_px = height;
    spec.tiled = layout < 2;
    spec.tile_width_px = spec.tile_height_px = 32;
    spec.rows_per_strip = 16;
    spec.bigtiff = bigtiff;
    const std::string tiff = dir + "/tiled.tif";
    ASSERT_EQ(test::writeTiff(tiff, spec, pixels), "");
    const uint64_t stored_bytes = uint64_t(width) * height * 3;  // uncompressed tiles
    BuildOptions options = syntheticOptions(tiff, dir + "/single.tess");
    options.codec = Codec::kZstd;
    ASSERT_TRUE(buildArchive(options));
    const std::vector<std::string> paths = buildParts(options, 4, dir);
    uint64_t read_by_all = 0;
    for (const std::string& path : paths) {
      auto part = Archive::openFile(path);
      ASSERT_TRUE(part) << part.error().message;
      const auto meta = nlohmann::json::parse((*part)->metadataJson())["split_part"];
      const uint64_t read = meta["stored_bytes_read"].get<uint64_t>();
      const uint64_t first = meta["rows"][0].get<uint64_t>();
      // Without seeking, the last part would read every tile above its rows too.
      if (path == paths.back()) {
        EXPECT_LE(read, stored_bytes * (height - first + 64) / height);
      }
      read_by_all += read;
    }
    // Each part reads its share plus at most a band above it; reading from the top would
    // make this 2.5 times the file.
    EXPECT_LT(read_by_all, stored_bytes * 3 / 2) << "layout " << layout;
    ASSERT_TRUE(mergeArchiveParts(paths, dir + "/merged.tess"));
    EXPECT_TRUE(test::readFileBytes(dir + "/single.tess") ==
                test::readFileBytes(dir + "/merged.tess"));
  }
}

/// The error of a merge that must fail, and that it left no output.
std::string mergeError(const std::vector<std::string>& paths, const std::string& output) {
  Result<MergeReport> merged = mergeArchiveParts(paths, output);
  EXPECT_FALSE(merged);
  EXPECT_FALSE(std::filesystem::exists(output));
  return merged ? std::string() : merged.error().message;
}

TEST(SplitMerge, RefusesMissingDuplicateAndForeignParts) {
  const std::string dir = test::testTempDir();
  const std::string out = dir + "/out.tess";
  BuildOptions options = syntheticOptions("synthetic:700x500:5:3", out);
  options.border_px = 1;
  const std::vector<std::string> parts = buildParts(options, 3, dir);

  EXPECT_NE(mergeError({parts[0], parts[2]}, out).find("parts 2"), std::string::npos);
  const std::string duplicate = mergeError({parts[0], parts[1], parts[1], parts[2]}, out);
  EXPECT_NE(duplicate.find("both part 2/3"), std::string::npos) << duplicate;

  BuildOptions other = options;
  other.quality = 70;
  other.output = dir + "/other-2.tess";
  ASSERT_TRUE(buildArchivePart(other, {2, 3}));
  const std::string foreign = mergeError({parts[0], other.output, parts[2]}, out);
  EXPECT_NE(foreign.find(other.output), std::string::npos) << foreign;
  EXPECT_NE(foreign.find("quality"), std::string::npos) << foreign;

  other = options;
  other.inputs = {"synthetic:700x500:6:3"};
  other.output = dir + "/input-2.tess";
  ASSERT_TRUE(buildArchivePart(other, {2, 3}));
  EXPECT_NE(mergeError({parts[0], other.output, parts[2]}, out).find("input"), std::string::npos);

  other = options;
  other.output = dir + "/four-2.tess";
  ASSERT_TRUE(buildArchivePart(other, {2, 4}));
  EXPECT_NE(mergeError({parts[0], other.output, parts[2]}, out).find("count"), std::string::npos);

  options.output = dir + "/whole.tess";
  ASSERT_TRUE(buildArchive(options));
  EXPECT_NE(mergeError({parts[0], parts[1], options.output}, out).find("not a part"),
            std::string::npos);
  EXPECT_TRUE(mergeArchiveParts({parts[2], parts[0], parts[1]}, out));
}

// The merge relies on the parts' "split_part" metadata: a field of the wrong type or out of
// range (a damaged or hand-made part) is refused naming the part and the field, where it threw
// from the JSON library before.
TEST(SplitMerge, RefusesAPartWithDamagedSplitMetadataNamingTheField) {
  const std::string dir = test::testTempDir();
  const std::string out = dir + "/out.tess";
  const std::vector<std::string> parts =
      buildParts(syntheticOptions("synthetic:300x200:5:3", out), 2, dir);
  auto part = Archive::openFile(parts[0]);
  ASSERT_TRUE(part) << part.error().message;
  const nlohmann::json metadata = nlohmann::json::parse((*part)->metadataJson());
  part->reset();
  const std::vector<uint8_t> bytes = test::readFileBytes(parts[0]);
  const std::string hostile = dir + "/hostile.tess";
  const struct {
    const char* pointer;
    nlohmann::json value;
    const char* message;
  } cases[] = {
      {"/split_part/count", "2", R"("split_part.count" is not an unsigned integer (it is "2"))"},
      {"/split_part/count", 100000, R"("split_part.count" is 100000, above 65536)"},
      {"/split_part/index", -1, R"("split_part.index" is not an unsigned integer (it is -1))"},
      {"/split_part/merge_level", 1.5, R"("split_part.merge_level" is not an unsigned)"},
      {"/split_part/rows", 5, R"("split_part.rows" is not a pair of row numbers)"},
      {"/split_part/rows/1", "x", R"("split_part.rows[1]" is not an unsigned integer)"},
      {"/split_part/archive_metadata", nlohmann::json::array(),
       R"("split_part.archive_metadata" is not an object)"},
      {"/split_part/archive_metadata/images", nlohmann::json::object(),
       R"("split_part.archive_metadata.images" is not an array of objects)"},
      {"/split_part/archive_metadata/build/codec", 3,
       R"("split_part.archive_metadata.build.codec" is not a codec's name)"},
      {"/split_part/archive_metadata/build/order", nullptr,
       R"("split_part.archive_metadata.build.order" is not a tile order's name)"},
      {"/split_part/archive_metadata/build/quality", "high",
       R"("split_part.archive_metadata.build.quality" is not an integer)"},
  };
  for (const auto& c : cases) {
    nlohmann::json damaged = metadata;
    damaged[nlohmann::json::json_pointer(c.pointer)] = c.value;
    ASSERT_TRUE(test::writeFileBytes(hostile, test::withMetadata(bytes, damaged.dump())));
    const std::string error = mergeError({hostile, parts[1]}, out);
    EXPECT_EQ(error.find(hostile + ": metadata "), 0u) << c.pointer << ": " << error;
    EXPECT_NE(error.find(c.message), std::string::npos) << c.pointer << ": " << error;
  }
  // A key the comparison of parts reads, absent from the first part: compared as none.
  nlohmann::json lacking = metadata;
  lacking["split_part"].erase("page_tiles_log2");
  ASSERT_TRUE(test::writeFileBytes(hostile, test::withMetadata(bytes, lacking.dump())));
  const std::string error = mergeError({hostile, parts[1]}, out);
  EXPECT_NE(error.find("page_tiles_log2"), std::string::npos) << error;
  EXPECT_TRUE(mergeArchiveParts(parts, out));
}

// A payload changed in a part after its build (a bad disk, a bad copy) fails the merge,
// naming the part and the tile, and leaves no output.
TEST(SplitMerge, RefusesAPartWhosePayloadFailsItsChecksum) {
  const std::string dir = test::testTempDir();
  const std::string out = dir + "/out.tess";
  BuildOptions options = syntheticOptions("synthetic:700x500:5:3", out);
  options.codec = Codec::kZstd;
  const std::vector<std::string> parts = buildParts(options, 3, dir);
  auto part = Archive::openFile(parts[1]);
  ASSERT_TRUE(part) << part.error().message;
  const ImageInfo info = (*part)->images()[0];
  std::optional<TileId> changed;
  uint64_t offset = 0;
  for (const TileId& tile : detail::tileOrder(info, 0, TileOrder::kHilbert)) {
    Result<TileEntry> entry = (*part)->tileEntry(tile);
    ASSERT_TRUE(entry);
    if (tile.level != 0 || entry->kind != TileKind::kEncoded) continue;
    changed = tile;
    offset = entry->offset_bytes + entry->length_bytes / 2;
  }
  ASSERT_TRUE(changed) << "part 2 holds no payload of level 0";
  part->reset();
  std::vector<uint8_t> bytes = test::readFileBytes(parts[1]);
  bytes[offset] ^= 0x20;
  {
    std::ofstream rewrite(parts[1], std::ios::binary | std::ios::trunc);
    rewrite.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
  }
  const std::string error = mergeError(parts, out);
  EXPECT_NE(error.find(parts[1]), std::string::npos) << error;
  EXPECT_NE(error.find(fmt::format("tile (0,{},{}) fails its checksum", changed->x, changed->y)),
            std::string::npos)
      << error;
}

TEST(SplitMerge, ParsesPartsCountedFromOne) {
  Result<PartSpec> part = parsePartSpec("3/8");
  ASSERT_TRUE(part);
  EXPECT_EQ(part->index, 3u);
  EXPECT_EQ(part->count, 8u);
  for (const char* bad : {"0/8", "9/8", "1/0", "3", "3/", "/8", "a/b", "3/8x", "-1/8", "1/65537"})
    EXPECT_FALSE(parsePartSpec(bad)) << bad;
}

TEST(SplitMerge, RefusesWhatItCannotSplit) {
  const std::string dir = test::testTempDir();
  BuildOptions options = syntheticOptions("synthetic:300x300:1:3", dir + "/p.tess");
  options.codec = Codec::kPtm;
  Result<BuildReport> ptm = buildArchivePart(options, {1, 2});
  ASSERT_FALSE(ptm);
  EXPECT_NE(ptm.error().message.find("ptm"), std::string::npos);
  options.codec = Codec::kJpeg;
  options.inputs.push_back("synthetic:100x100:2:3");
  EXPECT_FALSE(buildArchivePart(options, {1, 2}));
  EXPECT_FALSE(buildArchivePart(options, {3, 2}));
  EXPECT_FALSE(std::filesystem::exists(options.output));
  // A 16-bit source: every part is refused by name, none aborts on an 8-bit row buffer.
  test::PngSpec spec;
  spec.width_px = 40;
  spec.height_px = 300;
  spec.colour = test::PngColour::kGray;
  spec.bit_depth = 16;
  ASSERT_EQ(test::writePng(dir + "/wide.png", spec, std::vector<uint8_t>(40 * 300, 9)), "");
  options.inputs = {dir + "/wide.png"};
  options.codec = Codec::kZstd;
  for (uint32_t index : {1u, 2u}) {
    Result<BuildReport> wide = buildArchivePart(options, {index, 2});
    ASSERT_FALSE(wide);
    EXPECT_NE(wide.error().message.find("wide.png: u16 samples"), std::string::npos)
        << wide.error().message;
  }
  EXPECT_FALSE(std::filesystem::exists(options.output));
}

}  // namespace
}  // namespace tessera
