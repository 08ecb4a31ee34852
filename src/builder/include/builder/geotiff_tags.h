#pragma once
// The GeoTIFF and GDAL tags Tessera reads from sources (the TIFF reader) and writes back
// (`tessera export --to tiff`), with the registration libtiff needs before it handles them.

#include <cstdint>

namespace tessera::detail {

// GeoTIFF 1.1 (OGC 19-008r4, section 7.1) and GDAL's private tags.
inline constexpr uint32_t kTagModelPixelScale = 33550;
inline constexpr uint32_t kTagModelTiepoint = 33922;
inline constexpr uint32_t kTagModelTransformation = 34264;
inline constexpr uint32_t kTagGeoKeyDirectory = 34735;
inline constexpr uint32_t kTagGeoDoubleParams = 34736;
inline constexpr uint32_t kTagGeoAsciiParams = 34737;
inline constexpr uint32_t kTagGdalMetadata = 42112;
inline constexpr uint32_t kTagGdalNodata = 42113;

/// Teaches libtiff the tags above for every TIFF handle opened afterwards, by chaining a tag
/// extender onto whatever extender was installed before. Idempotent and thread-safe; call
/// before TIFFOpen.
void registerGeoTiffTags();

}  // namespace tessera::detail
