#pragma once
// The web-map writers of export.cpp, over XYZ tiles (256 px, zoom 0 one tile).

#include <cstdint>
#include <functional>
#include <string>

#include "export/export.h"
#include "serve/pictures.h"

namespace tessera::detail {

/// One XYZ tile of the export, in the order the writer asks for them.
struct XyzTile {
  uint32_t z = 0, x = 0, y = 0;
};

/// Every XYZ tile of `info` that holds part of the image, zoom 0 to xyzMaxZoom, row by row.
std::vector<XyzTile> xyzTilesOf(const ImageInfo& info);

[[nodiscard]] Result<ExportReport> exportPmtiles(const Archive& archive,
                                                 const std::string& out_path,
                                                 const ExportOptions& options);
[[nodiscard]] Result<ExportReport> exportMbtiles(const Archive& archive,
                                                 const std::string& out_path,
                                                 const ExportOptions& options);

}  // namespace tessera::detail
