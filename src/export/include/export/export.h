#pragma once
// `tessera export`: an archive's image as the pyramids other tools read (docs/export.md):
// a Deep Zoom folder (OpenSeadragon, vips), PMTiles v3 and MBTiles (web maps), a tiled
// pyramidal BigTIFF (GDAL, vips, QGIS). Tiles are
// copied as stored wherever the target's tile grid and the stored codec allow, and cut,
// scaled and encoded otherwise, by the same code that serves Deep Zoom and XYZ tiles.

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <tessera/archive.h>
#include <tessera/result.h>

namespace tessera::detail {

enum class ExportFormat : uint8_t { kDeepZoom, kPmtiles, kMbtiles, kTiff };

/// "dzi" (or "deepzoom"), "pmtiles", "mbtiles", "tiff" (or "tif"); nullopt for anything else.
std::optional<ExportFormat> parseExportFormat(std::string_view text);

/// The target's name for messages: "Deep Zoom", "PMTiles", "MBTiles" or "TIFF".
const char* exportFormatName(ExportFormat format);

struct ExportOptions {
  ExportFormat format = ExportFormat::kDeepZoom;
  uint32_t image = 0;     ///< which image of the archive
  int jpeg_quality = 85;  ///< for tiles that must be encoded as JPEG
  /// PMTiles: entries per leaf directory; 0 (default) puts every entry in the root directory
  /// when it fits in the first 16 KiB, and uses leaves of 4096 entries otherwise.
  uint32_t pmtiles_leaf_entries = 0;
  /// Called after each tile with (tiles done, tiles in all); may be empty.
  std::function<void(uint64_t, uint64_t)> on_progress;
};

struct ExportReport {
  uint64_t tiles = 0;         ///< tiles written (PMTiles: addressed tiles)
  uint64_t tiles_copied = 0;  ///< of those, stored payloads copied without decoding
  /// Of those, tiles of one uniform stored tile, whose picture is encoded once per colour (and
  /// Deep Zoom size) and shared.
  uint64_t tiles_uniform = 0;
  uint64_t bytes = 0;       ///< bytes of the output (folder: every file)
  std::string tile_format;  ///< "jpg" or "png"; TIFF: "jpeg", "deflate" or "zstd"
  /// TIFF: the source's GeoTIFF tags were written back (docs/export.md).
  bool georeferenced = false;
  /// What was exported differently from what the archive holds, one line each (for example a
  /// georeference entry that is not what its tag holds, left out).
  std::vector<std::string> warnings;
};

/// Writes the export to `out_path`. Nothing is visible at the output until it is complete:
/// a PMTiles, MBTiles or TIFF file is renamed into place, a Deep Zoom folder `NAME_files` is
/// written under a temporary name and renamed before `NAME.dzi` is committed. `out_path`
/// must end in ".dzi" for Deep Zoom; an existing `NAME_files` is refused (never merged).
/// Errors name the output and the tile. An image of u16 or f32 samples goes to TIFF only,
/// samples kept as they are; the other targets refuse it with kUnsupported naming the image and
/// its sample type.
[[nodiscard]] Result<ExportReport> exportArchive(const Archive& archive,
                                                 const std::string& out_path,
                                                 const ExportOptions& options);

}  // namespace tessera::detail
