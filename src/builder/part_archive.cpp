#include <cstring>

#include <fmt/format.h>

#include "archive_writer.h"
#include "codecs/encode.h"
#include "format/checksum.h"
#include "output/output_file.h"
#include "part_build.h"
#include "tile_cutter.h"

namespace tessera::detail {

namespace {

/// Rows held whole in memory, as the tile cutter reads them.
struct BufferRows final : LevelRows {
  const uint8_t* data = nullptr;
  const uint8_t* row(uint32_t y) const override { return data + size_t(y) * width_px * channels; }
};

/// Image 0: the whole image's directory with the tiles the part owns, taken from the window
/// archive (spool_offset is the payload's offset there).
Result<SpooledImage> ownedTiles(const PartLayout& layout, const Archive* window) {
  const ImageInfo& info = layout.info;
  SpooledImage image;
  image.info = info;
  image.entries.resize(info.level_count);
  for (uint32_t l = 0; l < info.level_count; ++l)
    image.entries[l].resize(size_t(info.tilesX(l)) * info.tilesY(l));
  if (!window) return image;
  for (uint32_t l = 0; l < layout.plan.merge_level; ++l) {
    const uint32_t shift = tileRowAt(info, l, layout.window_first_row);
    for (uint32_t y = tileRowAt(info, l, layout.first_row); y < tileRowAt(info, l, layout.end_row);
         ++y) {
      for (uint32_t x = 0; x < info.tilesX(l); ++x) {
        TESSERA_ASSIGN_OR_RETURN(TileEntry entry, window->tileEntry({0, l, x, y - shift}));
        image.entries[l][size_t(y) * info.tilesX(l) + x] = spoolEntryOf(entry);
      }
    }
  }
  return image;
}

}  // namespace

SpoolEntry spoolEntryOf(const TileEntry& entry) {
  SpoolEntry spooled;
  spooled.kind = entry.kind;
  spooled.codec = entry.codec;
  spooled.uniform_rgba = entry.uniform_rgba;
  spooled.length_bytes = entry.length_bytes;
  spooled.checksum = entry.checksum;
  spooled.spool_offset = entry.offset_bytes;
  return spooled;
}

TileOrder buildOrderOf(const nlohmann::json& archive_metadata) {
  const std::string name = archive_metadata["build"]["order"].get<std::string>();
  return name == "hilbert"    ? TileOrder::kHilbert
         : name == "quadtree" ? TileOrder::kQuadtree
                              : TileOrder::kRowMajor;
}

ImageInfo partRowsInfo(const ImageInfo& info, uint32_t merge_level, uint32_t rows) {
  ImageInfo level;
  level.width_px = info.levelWidthPx(merge_level);
  level.height_px = rows;
  level.channels = info.channels;
  level.tile_size_px = info.tile_size_px;
  level.border_px = 0;
  level.page_tiles_log2 = info.page_tiles_log2;
  level.default_codec = findEncoder(Codec::kZstd) ? Codec::kZstd : Codec::kRaw;
  level.level_count = levelCountFor(level.width_px, level.height_px, level.tile_size_px);
  level.name = kPartRowsImageName;
  return level;
}

Result<uint64_t> writePartArchive(const PartLayout& layout, const Archive* window,
                                  const std::vector<uint8_t>& level_rows,
                                  const nlohmann::json& part, const std::string& output) {
  std::vector<SpooledImage> images;
  TESSERA_ASSIGN_OR_RETURN(SpooledImage owned, ownedTiles(layout, window));
  images.push_back(std::move(owned));
  std::vector<std::vector<uint8_t>> row_payloads;
  const size_t row_bytes =
      size_t(layout.info.levelWidthPx(layout.plan.merge_level)) * layout.info.channels;
  if (!level_rows.empty()) {
    SpooledImage rows_image;
    rows_image.info =
        partRowsInfo(layout.info, layout.plan.merge_level, uint32_t(level_rows.size() / row_bytes));
    const ImageInfo& info = rows_image.info;
    rows_image.entries.resize(info.level_count);
    BufferRows buffer;
    buffer.data = level_rows.data();
    buffer.width_px = info.width_px;
    buffer.height_px = info.height_px;
    buffer.channels = info.channels;
    std::vector<uint8_t> tile(info.storedTileBytes());
    const uint32_t side = info.storedTileSidePx();
    for (uint32_t l = 0; l < info.level_count; ++l) {
      rows_image.entries[l].resize(size_t(info.tilesX(l)) * info.tilesY(l));
      if (l > 0) {
        for (SpoolEntry& entry : rows_image.entries[l]) entry.kind = TileKind::kUniform;
        continue;
      }
      for (uint32_t y = 0; y < info.tilesY(0); ++y) {
        for (uint32_t x = 0; x < info.tilesX(0); ++x) {
          cutTile(buffer, info.tile_size_px, 0, x, y, tile.data());
          TESSERA_ASSIGN_OR_RETURN(
              std::vector<uint8_t> payload,
              encodeTile(info.default_codec,
                         {tile.data(), side, side, info.channels, size_t(side) * info.channels},
                         {}));
          SpoolEntry& entry = rows_image.entries[0][size_t(y) * info.tilesX(0) + x];
          entry.kind = TileKind::kEncoded;
          entry.codec = info.default_codec;
          entry.length_bytes = uint32_t(payload.size());
          entry.checksum = checksum64(payload);
          entry.spool_offset = row_payloads.size();
          row_payloads.push_back(std::move(payload));
        }
      }
    }
    images.push_back(std::move(rows_image));
  }
  auto fetch = [&](const TileId& tile, const SpoolEntry& entry,
                   std::span<uint8_t> out) -> Result<void> {
    if (tile.image == 1) {
      std::memcpy(out.data(), row_payloads[entry.spool_offset].data(), out.size());
      return {};
    }
    TileEntry stored;
    stored.kind = entry.kind;
    stored.codec = entry.codec;
    stored.offset_bytes = entry.spool_offset;
    stored.length_bytes = entry.length_bytes;
    stored.checksum = entry.checksum;
    const uint32_t shift = tileRowAt(layout.info, tile.level, layout.window_first_row);
    TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> payload,
                             window->readPayload({0, tile.level, tile.x, tile.y - shift}, stored));
    std::memcpy(out.data(), payload.data(), out.size());
    return {};
  };
  nlohmann::json image_names = nlohmann::json::array();
  for (const SpooledImage& image : images) image_names.push_back({{"name", image.info.name}});
  const nlohmann::json metadata = {
      {"format", "tessera"},
      {"format_version", fmt::format("{}.{}", kFormatVersionMajor, kFormatVersionMinor)},
      {"created_by", "tessera build --part"},
      {"images", image_names},
      {"split_part", part}};
  TESSERA_ASSIGN_OR_RETURN(TempFile out, TempFile::create(output));
  TESSERA_ASSIGN_OR_RETURN(
      WrittenArchive written,
      writeArchive(fetch, images, buildOrderOf(part["archive_metadata"]), metadata, out));
  TESSERA_TRY(out.commit());
  return written.file_bytes;
}

}  // namespace tessera::detail
