#pragma once
// Pictures of one-colour tiles for the export writers. A flat area of an image is stored as
// uniform tiles with no payload; cutting each of them afresh would encode the same picture once
// per tile, so each distinct colour is encoded once and reused.

#include <cstdint>
#include <unordered_map>

#include <tessera/archive.h>
#include <tessera/result.h>

#include "serve/pictures.h"

namespace tessera::detail {

/// XYZ pictures of uniform stored tiles, encoded on first use. Owned by one thread.
class UniformPictures {
 public:
  UniformPictures(const ImageInfo& info, PictureFormat format, int jpeg_quality)
      : info_(info), format_(format), jpeg_quality_(jpeg_quality) {}

  /// What renderXyzTile returns for an XYZ tile that is wholly a stored tile of colour
  /// `texel` (xyzStoredTile, uniformTexel). The picture lives as long as this object.
  [[nodiscard]] Result<const Picture*> xyz(UniformTexel texel);
  /// What renderDziTile returns for a Deep Zoom tile of `width_px` x `height_px` cut from a
  /// stored tile of colour `texel` (dziStoredTile, uniformTexel). Lives as long as this object.
  [[nodiscard]] Result<const Picture*> dzi(UniformTexel texel, uint32_t width_px,
                                           uint32_t height_px);
  /// Tiles answered by xyz() and dzi() so far.
  uint64_t tilesServed() const { return tiles_served_; }
  PictureFormat format() const { return format_; }
  int jpegQuality() const { return jpeg_quality_; }

 private:
  const ImageInfo& info_;
  PictureFormat format_;
  int jpeg_quality_;
  uint64_t tiles_served_ = 0;
  std::unordered_map<uint32_t, Picture> xyz_;  ///< by UniformTexel::rgba; nodes never move
  /// By colour, width and height (rgba << 32 | width << 16 | height: sides under 2^16).
  std::unordered_map<uint64_t, Picture> dzi_;
};

/// renderXyzTile for the export writers: a tile that is wholly one uniform stored tile comes
/// from `uniforms` instead of being cut and encoded again.
[[nodiscard]] Result<Picture> exportXyzTile(const Archive& archive, uint32_t image, uint32_t z,
                                            uint32_t x, uint32_t y, UniformPictures& uniforms);

/// renderDziTile for the export writers, uniform tiles from `uniforms` as in exportXyzTile.
[[nodiscard]] Result<Picture> exportDziTile(const Archive& archive, uint32_t image,
                                            uint32_t dz_level, uint32_t col, uint32_t row,
                                            UniformPictures& uniforms);

}  // namespace tessera::detail
