#pragma once
// What the builder recorded about an image in the archive's metadata (docs/format.md,
// "Metadata"), for the server's info.json and the exports.

#include <cstdint>
#include <string>

#include <tessera/archive.h>

namespace tessera::detail {

/// The JSON object the builder kept under `images[image].georeference` (a GeoTIFF source's
/// tags and EPSG code), serialised; empty when the image has none or the metadata does not
/// hold an object there.
std::string imageGeoreferenceJson(const Archive& archive, uint32_t image);

}  // namespace tessera::detail
