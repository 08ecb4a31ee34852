#pragma once
// The web-map writers of export.cpp, over XYZ tiles (256 px, zoom 0 one tile).

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <tiffio.h>

#include "export/export.h"
#include "serve/pictures.h"

namespace tessera::detail {

/// One XYZ tile of the export, in the order the writer asks for them.
struct XyzTile {
  uint32_t z = 0, x = 0, y = 0;
};

/// Every XYZ tile of `info` that holds part of the image, zoom 0 to xyzMaxZoom, row by row.
std::vector<XyzTile> xyzTilesOf(const ImageInfo& info);

/// For writers that need a path (SQLite, libtiff): checks `out_path` (checkOutputPath), calls
/// `write` with a temporary path beside it, then syncs that file and renames it into place,
/// asking checkOutputPath again first. On any failure the temporary file is removed and
/// nothing is left at `out_path`.
[[nodiscard]] Result<void> writeThroughPartialFile(
    const std::string& out_path, const std::function<Result<void>(const std::string&)>& write);

/// Sets the GeoTIFF and GDAL tags held by `georeference_json` (an image's `georeference`
/// metadata, docs/format.md) on the TIFF directory being written. An entry that does not hold
/// what its tag does is left out and named in `report.warnings`; `report.georeferenced` says
/// whether any tag was set.
void setGeoreferenceTags(TIFF* tiff, const std::string& georeference_json, ExportReport& report);

/// A Deep Zoom folder (`out_path` NAME.dzi) or zip file (NAME.zip).
[[nodiscard]] Result<ExportReport> exportDeepZoom(const Archive& archive,
                                                  const std::string& out_path,
                                                  const ExportOptions& options);
[[nodiscard]] Result<ExportReport> exportPmtiles(const Archive& archive,
                                                 const std::string& out_path,
                                                 const ExportOptions& options);
[[nodiscard]] Result<ExportReport> exportMbtiles(const Archive& archive,
                                                 const std::string& out_path,
                                                 const ExportOptions& options);
[[nodiscard]] Result<ExportReport> exportTiff(const Archive& archive, const std::string& out_path,
                                              const ExportOptions& options);

}  // namespace tessera::detail
