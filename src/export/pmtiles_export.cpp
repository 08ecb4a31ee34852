// PMTiles v3 in one pass: the header and a root directory reserved in the first 16 KiB, tile
// blobs after it in tile id order (identical blobs stored once, runs of them as one entry),
// then the metadata and, when the root would not fit, leaf directories.
#include <algorithm>
#include <unordered_map>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "export/pmtiles.h"
#include "export_writers.h"
#include "output/file_appender.h"
#include "output/output_file.h"
#include "tile_blobs.h"
#include "uniform_pictures.h"

namespace tessera::detail {

namespace {

using pmtiles::Entry;

std::span<const uint8_t> asBytes(std::string_view text) {
  return {reinterpret_cast<const uint8_t*>(text.data()), text.size()};
}

struct Directories {
  std::vector<uint8_t> root;
  std::vector<uint8_t> leaves;
};

// The root alone when it fits beside the header (and no leaf size is asked for); else leaves
// of `per_leaf` entries (default 4096), doubled until the root of leaf pointers fits.
Directories layoutDirectories(const std::vector<Entry>& entries, uint32_t leaf_entries) {
  const uint64_t root_room = pmtiles::kRootWindowBytes - pmtiles::kHeaderBytes;
  Directories out;
  out.root = pmtiles::encodeDirectory(entries);
  if (leaf_entries == 0 && out.root.size() <= root_room) return out;
  for (size_t per_leaf = leaf_entries ? leaf_entries : 4096;; per_leaf *= 2) {
    std::vector<Entry> pointers;
    out.leaves.clear();
    for (size_t first = 0; first < entries.size(); first += per_leaf) {
      const size_t last = std::min(entries.size(), first + per_leaf);
      const std::vector<uint8_t> leaf = pmtiles::encodeDirectory(std::vector<Entry>(
          entries.begin() + ptrdiff_t(first), entries.begin() + ptrdiff_t(last)));
      pointers.push_back({entries[first].tile_id, out.leaves.size(), uint32_t(leaf.size()), 0});
      out.leaves.insert(out.leaves.end(), leaf.begin(), leaf.end());
    }
    out.root = pmtiles::encodeDirectory(pointers);
    if (out.root.size() <= root_room) return out;
  }
}

// Where each XYZ tile's blob comes from: the stored payload when it is the tile exactly, the
// picture of a uniform tile encoded once per colour, else the tile cut and encoded.
class TileSources {
 public:
  TileSources(const Archive& archive, const ExportOptions& options, PictureFormat format,
              TileBlobs& blobs)
      : archive_(archive),
        info_(archive.images()[options.image]),
        options_(options),
        format_(format),
        blobs_(blobs),
        uniforms_(info_, format, options.jpeg_quality) {}

  Result<PlacedBlob> place(const XyzTile& t, ExportReport& report) {
    if (const std::optional<TileId> stored = xyzStoredTile(info_, options_.image, t.z, t.x, t.y)) {
      TESSERA_ASSIGN_OR_RETURN(const TileEntry entry, archive_.tileEntry(*stored));
      if (entry.kind == TileKind::kEncoded && browserReady(info_, entry.codec, format_)) {
        ++report.tiles_copied;
        return blobs_.copy(*stored, entry);
      }
      if (const std::optional<UniformTexel> texel = uniformTexel(info_, entry)) {
        ++report.tiles_uniform;
        if (auto found = placed_uniform_.find(texel->rgba); found != placed_uniform_.end())
          return PlacedBlob{found->second.offset_bytes, found->second.length_bytes, false};
        TESSERA_ASSIGN_OR_RETURN(const Picture* picture, uniforms_.xyz(*texel));
        TESSERA_ASSIGN_OR_RETURN(const PlacedBlob placed, blobs_.put(asBytes(picture->bytes)));
        placed_uniform_.emplace(texel->rgba, placed);
        return placed;
      }
    }
    Result<Picture> picture =
        renderXyzTile(archive_, options_.image, t.z, t.x, t.y, format_, options_.jpeg_quality);
    if (!picture)
      return fail(picture.error().code,
                  fmt::format("XYZ tile {}/{}/{}: {}", t.z, t.x, t.y, picture.error().message));
    report.tiles_copied += picture->copied ? 1 : 0;
    return blobs_.put(asBytes(picture->bytes));
  }

 private:
  const Archive& archive_;
  const ImageInfo& info_;
  const ExportOptions& options_;
  PictureFormat format_;
  TileBlobs& blobs_;
  UniformPictures uniforms_;
  std::unordered_map<uint32_t, PlacedBlob> placed_uniform_;  ///< by UniformTexel::rgba
};

std::string metadataJson(const Archive& archive, const ImageInfo& info,
                         const std::string& tile_format) {
  nlohmann::json json = {{"name", info.name.empty() ? archive.name() : info.name},
                         {"format", tile_format},
                         {"type", "baselayer"},
                         {"tessera", {{"width", info.width_px}, {"height", info.height_px}}}};
  return json.dump();
}

}  // namespace

Result<ExportReport> exportPmtiles(const Archive& archive, const std::string& out_path,
                                   const ExportOptions& options) {
  const ImageInfo& info = archive.images()[options.image];
  const PictureFormat format = dziFormat(info);
  std::vector<XyzTile> tiles = xyzTilesOf(info);
  std::vector<std::pair<uint64_t, XyzTile>> ordered;
  for (const XyzTile& t : tiles) ordered.push_back({pmtiles::tileId(t.z, t.x, t.y), t});
  std::sort(ordered.begin(), ordered.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });

  TESSERA_ASSIGN_OR_RETURN(TempFile out, TempFile::create(out_path));
  TileBlobs blobs(archive, out, pmtiles::kRootWindowBytes);
  TileSources sources(archive, options, format, blobs);
  std::vector<Entry> entries;
  ExportReport report;
  report.tile_format = dziExtension(format);
  uint64_t contents = 0;
  for (const auto& [id, t] : ordered) {
    Result<PlacedBlob> placed = sources.place(t, report);
    // Copied payloads are verified a run at a time, so an error names the stored tile it is
    // about (the archive's message), which need not be the XYZ tile placed now.
    if (!placed)
      return fail(placed.error().code, fmt::format("{}: {}", out_path, placed.error().message));
    contents += placed->fresh ? 1 : 0;
    Entry* last = entries.empty() ? nullptr : &entries.back();
    if (last && last->offset == placed->offset_bytes && last->tile_id + last->run_length == id)
      ++last->run_length;
    else
      entries.push_back({id, placed->offset_bytes, placed->length_bytes, 1});
    ++report.tiles;
    if (options.on_progress) options.on_progress(report.tiles, ordered.size());
  }
  Result<void> flushed = blobs.flush();
  if (!flushed)
    return fail(flushed.error().code, fmt::format("{}: {}", out_path, flushed.error().message));
  FileAppender& appender = blobs.appender();
  pmtiles::Header header;
  header.tile_data_offset = pmtiles::kRootWindowBytes;
  header.tile_data_bytes = appender.end() - pmtiles::kRootWindowBytes;
  const Directories directories = layoutDirectories(entries, options.pmtiles_leaf_entries);
  const std::string metadata = metadataJson(archive, info, report.tile_format);
  TESSERA_ASSIGN_OR_RETURN(header.metadata_offset, appender.append(asBytes(metadata)));
  header.metadata_bytes = metadata.size();
  TESSERA_ASSIGN_OR_RETURN(header.leaves_offset, appender.append(directories.leaves));
  header.leaves_bytes = directories.leaves.size();
  TESSERA_TRY(appender.flush());
  header.root_offset = pmtiles::kHeaderBytes;
  header.root_bytes = directories.root.size();
  header.addressed_tiles = ordered.size();
  header.tile_entries = entries.size();
  header.tile_contents = contents;
  header.tile_type =
      format == PictureFormat::kPng ? pmtiles::TileType::kPng : pmtiles::TileType::kJpeg;
  header.max_zoom = uint8_t(xyzMaxZoom(info));
  std::vector<uint8_t> head = pmtiles::encodeHeader(header);
  head.insert(head.end(), directories.root.begin(), directories.root.end());
  head.resize(pmtiles::kRootWindowBytes, 0);
  TESSERA_TRY(out.pwrite(0, head));
  report.bytes = appender.end();
  TESSERA_TRY(out.commit());
  return report;
}

std::vector<XyzTile> xyzTilesOf(const ImageInfo& info) {
  std::vector<XyzTile> tiles;
  const uint32_t max_zoom = xyzMaxZoom(info);
  for (uint32_t z = 0; z <= max_zoom; ++z) {
    const uint32_t scale = max_zoom - z;
    const uint32_t cols = (scaledWidthPx(info, scale) + kXyzTileSizePx - 1) / kXyzTileSizePx;
    const uint32_t rows = (scaledHeightPx(info, scale) + kXyzTileSizePx - 1) / kXyzTileSizePx;
    for (uint32_t y = 0; y < rows; ++y)
      for (uint32_t x = 0; x < cols; ++x) tiles.push_back({z, x, y});
  }
  return tiles;
}

}  // namespace tessera::detail
