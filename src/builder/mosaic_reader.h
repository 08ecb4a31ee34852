#pragma once
// Image files placed by a mosaic manifest, read as one image (docs/builder.md, "Mosaic
// manifests").

#include <memory>
#include <string>

#include <tessera/result.h>

#include "band_reader.h"

namespace tessera::detail {

/// Opens the mosaic of the manifest at `path` (mosaic_manifest.h). Every image's header is
/// read once first, failing naming the manifest and the entry for a missing or unreadable
/// file, a stated width or height the file does not have, channels or a sample type other than
/// the first image's, an image past the canvas, or a background of the wrong length or range.
/// Bands then open only the images they cross, in turn, and close each past its last row, so
/// the images crossing one band are the most open at once; a skip opens nothing above the new
/// position (and a TIFF image reads none of its strips or tiles above it). Where images
/// overlap, the later entry wins; pixels no image covers are the background.
[[nodiscard]] Result<std::unique_ptr<BandReader>> openMosaicReader(const std::string& path);

}  // namespace tessera::detail
