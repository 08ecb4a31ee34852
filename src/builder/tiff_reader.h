#pragma once
// TIFF-specific pieces shared with tools that write TIFFs (bench/make_tiff.cpp) and tests.

namespace tessera::detail {

/// Teaches libtiff the GeoTIFF and GDAL tags (ModelPixelScale 33550, ModelTiepoint 33922,
/// ModelTransformation 34264, GeoKeyDirectory 34735, GeoDoubleParams 34736, GeoAsciiParams
/// 34737, GDAL_METADATA 42112, GDAL_NODATA 42113) for every TIFF handle opened afterwards, by
/// chaining a tag extender onto whatever extender was installed before. Idempotent and
/// thread-safe; call before TIFFOpen.
void registerGeoTiffTags();

}  // namespace tessera::detail
