// Exports of images with flat areas, stored as uniform (and empty) tiles without payload: each
// distinct uniform picture is stored once in PMTiles, and every tile of every target still
// equals what the server cuts for it. The PMTiles file is parsed here from the spec's layout.
#include "uniform_pictures.h"

#include <filesystem>
#include <map>
#include <set>

#include <gtest/gtest.h>

#include <tessera/open.h>

#include "export/export.h"
#include "export/pmtiles.h"
#include "export_writers.h"
#include "serve/pictures.h"
#include "support/archive_fixture.h"
#include "support/test_images.h"

namespace tessera::detail {
namespace {

namespace fs = std::filesystem;

// Tiles of 256 px in 2 x 2 blocks of one palette colour (so the next level is uniform too),
// except two tiles of the same gradient (kPatternTiles), whose payloads are equal but stored
// apart.
Image flatImage(uint32_t cols, uint32_t rows, uint32_t channels,
                const std::vector<std::vector<uint8_t>>& palette) {
  Image image(cols * 256, rows * 256, channels);
  for (uint32_t y = 0; y < image.height_px; ++y) {
    for (uint32_t x = 0; x < image.width_px; ++x) {
      const uint32_t tx = x / 256, ty = y / 256;
      const bool pattern = (tx == 1 && ty == 1) || (tx == 3 && ty == 2);
      uint8_t* texel = image.row(y) + size_t(x) * channels;
      for (uint32_t c = 0; c < channels; ++c)
        texel[c] = pattern ? uint8_t((x % 256 + 3 * (y % 256) + 40 * c) & 0xff)
                           : palette[(tx / 2 + ty / 2) % palette.size()][c];
    }
  }
  return image;
}

uint64_t le64(const std::vector<uint8_t>& bytes, size_t at) {
  uint64_t value = 0;
  for (int i = 7; i >= 0; --i) value = value << 8 | bytes.at(at + size_t(i));
  return value;
}

uint64_t varint(const std::vector<uint8_t>& bytes, size_t& at) {
  uint64_t value = 0;
  for (int shift = 0;; shift += 7) {
    const uint8_t byte = bytes.at(at++);
    value |= uint64_t(byte & 0x7f) << shift;
    if (!(byte & 0x80)) return value;
  }
}

// A root directory (spec v3, "Directories"): columns of id deltas, run lengths, lengths and
// offsets, an offset of 0 meaning right after the previous entry.
std::vector<pmtiles::Entry> rootEntries(const std::vector<uint8_t>& file) {
  size_t at = size_t(le64(file, 8));
  const size_t count = size_t(varint(file, at));
  std::vector<pmtiles::Entry> entries(count);
  uint64_t id = 0;
  for (pmtiles::Entry& e : entries) e.tile_id = id += varint(file, at);
  for (pmtiles::Entry& e : entries) e.run_length = uint32_t(varint(file, at));
  for (pmtiles::Entry& e : entries) e.length = uint32_t(varint(file, at));
  for (size_t i = 0; i < count; ++i) {
    const uint64_t offset = varint(file, at);
    entries[i].offset =
        offset == 0 && i > 0 ? entries[i - 1].offset + entries[i - 1].length : offset - 1;
  }
  return entries;
}

class UniformExportTest : public ::testing::TestWithParam<int> {
 protected:
  void SetUp() override {
    dir_ = test::testTempDir() + "/export-uniform-" + std::to_string(GetParam()) + "/";
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    BuildOptions options;
    Image image;
    if (GetParam() == 0) {
      options.codec = Codec::kJpeg;
      image = flatImage(4, 4, 3, {{200, 30, 30}, {20, 90, 220}, {240, 240, 240}});
    } else {
      // Gray + alpha in PNG: a transparent block (stored empty) and a half-transparent one.
      options.codec = Codec::kPng;
      image = flatImage(4, 4, 2, {{0, 0}, {90, 128}, {250, 255}});
    }
    built_ = test::buildFromImage(image, options, dir_);
    Result<std::shared_ptr<Archive>> opened = openArchive(built_.path);
    ASSERT_TRUE(opened) << opened.error().message;
    archive_ = *opened;
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string dir_;
  test::BuiltArchive built_;
  std::shared_ptr<Archive> archive_;
};

TEST_P(UniformExportTest, PmtilesStoresEachUniformPictureOnce) {
  ExportOptions options;
  options.format = ExportFormat::kPmtiles;
  const std::string out = dir_ + "flat.pmtiles";
  Result<ExportReport> report = exportArchive(*archive_, out, options);
  ASSERT_TRUE(report) << report.error().message;
  const std::vector<uint8_t> file = test::readFileBytes(out);
  ASSERT_GE(file.size(), size_t(pmtiles::kRootWindowBytes));
  const uint64_t data_offset = le64(file, 56), data_bytes = le64(file, 64);
  const std::vector<pmtiles::Entry> entries = rootEntries(file);

  const ImageInfo& info = archive_->images()[0];
  const PictureFormat format = dziFormat(info);
  std::map<uint32_t, std::set<uint64_t>> offsets_by_colour;
  std::map<uint64_t, uint32_t> blobs;  // offset -> length
  std::set<uint64_t> pattern_offsets;
  size_t uniform_tiles = 0;
  for (const XyzTile& t : xyzTilesOf(info)) {
    const uint64_t id = pmtiles::tileId(t.z, t.x, t.y);
    auto entry = std::find_if(entries.begin(), entries.end(), [&](const pmtiles::Entry& e) {
      return e.tile_id <= id && id < e.tile_id + e.run_length;
    });
    ASSERT_NE(entry, entries.end()) << t.z << "/" << t.x << "/" << t.y;
    ASSERT_LE(entry->offset + entry->length, data_bytes);
    const auto begin = file.begin() + ptrdiff_t(data_offset + entry->offset);
    const std::string bytes(begin, begin + entry->length);
    Result<Picture> expected = renderXyzTile(*archive_, 0, t.z, t.x, t.y, format, 85);
    ASSERT_TRUE(expected) << expected.error().message;
    EXPECT_EQ(bytes, expected->bytes) << t.z << "/" << t.x << "/" << t.y;
    blobs[entry->offset] = entry->length;
    if (t.z == xyzMaxZoom(info) && ((t.x == 1 && t.y == 1) || (t.x == 3 && t.y == 2)))
      pattern_offsets.insert(entry->offset);
    if (const std::optional<TileId> stored = xyzStoredTile(info, 0, t.z, t.x, t.y)) {
      Result<TileEntry> stored_entry = archive_->tileEntry(*stored);
      ASSERT_TRUE(stored_entry);
      if (const std::optional<UniformTexel> texel = uniformTexel(info, *stored_entry)) {
        offsets_by_colour[texel->rgba].insert(entry->offset);
        ++uniform_tiles;
      }
    }
  }
  // Three colours, each over several tiles at two zooms: one blob per colour.
  EXPECT_EQ(offsets_by_colour.size(), 3u);
  EXPECT_GT(uniform_tiles, 2 * offsets_by_colour.size());
  EXPECT_EQ(report->tiles_uniform, uniform_tiles);
  for (const auto& [colour, offsets] : offsets_by_colour)
    EXPECT_EQ(offsets.size(), 1u) << "colour " << std::hex << colour;
  // The two gradient tiles' payloads, equal bytes at two places in the archive, stored once.
  EXPECT_EQ(pattern_offsets.size(), 1u);
  // Nothing else in the tile data: every distinct blob once, back to back.
  uint64_t sum = 0;
  for (const auto& [offset, length] : blobs) sum += length;
  EXPECT_EQ(sum, data_bytes);
  EXPECT_EQ(le64(file, 88), blobs.size());  // tile contents
}

TEST_P(UniformExportTest, DeepZoomAndMbtilesTilesEqualTheServers) {
  ExportOptions options;
  Result<ExportReport> dzi = exportArchive(*archive_, dir_ + "flat.dzi", options);
  ASSERT_TRUE(dzi) << dzi.error().message;
  const ImageInfo& info = archive_->images()[0];
  const PictureFormat format = dziFormat(info);
  uint64_t files = 0;
  for (const auto& entry : fs::recursive_directory_iterator(dir_ + "flat_files")) {
    if (!entry.is_regular_file()) continue;
    const uint32_t level = uint32_t(std::stoul(entry.path().parent_path().filename().string()));
    uint32_t col = 0, row = 0;
    ASSERT_EQ(std::sscanf(entry.path().filename().c_str(), "%u_%u.", &col, &row), 2);
    Result<Picture> expected = renderDziTile(*archive_, 0, level, col, row, format, 85);
    ASSERT_TRUE(expected) << entry.path() << ": " << expected.error().message;
    const std::vector<uint8_t> bytes = test::readFileBytes(entry.path().string());
    EXPECT_EQ(std::string(bytes.begin(), bytes.end()), expected->bytes) << entry.path();
    ++files;
  }
  EXPECT_EQ(files, dzi->tiles);
  EXPECT_GT(dzi->tiles_uniform, 0u);

  // MBTiles goes through exportXyzTile, which the PMTiles test above does not: tile by tile.
  UniformPictures uniforms(info, format, 85);
  for (const XyzTile& t : xyzTilesOf(info)) {
    Result<Picture> exported = exportXyzTile(*archive_, 0, t.z, t.x, t.y, uniforms);
    Result<Picture> expected = renderXyzTile(*archive_, 0, t.z, t.x, t.y, format, 85);
    ASSERT_TRUE(exported && expected) << t.z << "/" << t.x << "/" << t.y;
    EXPECT_EQ(exported->bytes, expected->bytes) << t.z << "/" << t.x << "/" << t.y;
  }
}

INSTANTIATE_TEST_SUITE_P(RgbJpegAndGrayAlphaPng, UniformExportTest, ::testing::Values(0, 1));

}  // namespace
}  // namespace tessera::detail
