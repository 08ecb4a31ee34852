#include "uniform_pictures.h"

namespace tessera::detail {

Result<const Picture*> UniformPictures::xyz(UniformTexel texel) {
  ++tiles_served_;
  if (auto found = xyz_.find(texel.rgba); found != xyz_.end()) return &found->second;
  TESSERA_ASSIGN_OR_RETURN(Picture picture,
                           uniformXyzPicture(info_, texel, format_, jpeg_quality_));
  return &xyz_.emplace(texel.rgba, std::move(picture)).first->second;
}

Result<const Picture*> UniformPictures::dzi(UniformTexel texel, uint32_t width_px,
                                            uint32_t height_px) {
  ++tiles_served_;
  const uint64_t key = uint64_t(texel.rgba) << 32 | uint64_t(width_px) << 16 | height_px;
  if (auto found = dzi_.find(key); found != dzi_.end()) return &found->second;
  TESSERA_ASSIGN_OR_RETURN(Picture picture, uniformDziPicture(info_, texel, width_px, height_px,
                                                              format_, jpeg_quality_));
  return &dzi_.emplace(key, std::move(picture)).first->second;
}

Result<Picture> exportXyzTile(const Archive& archive, uint32_t image, uint32_t z, uint32_t x,
                              uint32_t y, UniformPictures& uniforms) {
  const ImageInfo& info = archive.images()[image];
  if (const std::optional<TileId> stored = xyzStoredTile(info, image, z, x, y)) {
    TESSERA_ASSIGN_OR_RETURN(TileEntry entry, archive.tileEntry(*stored));
    if (const std::optional<UniformTexel> texel = uniformTexel(info, entry)) {
      TESSERA_ASSIGN_OR_RETURN(const Picture* picture, uniforms.xyz(*texel));
      return *picture;
    }
  }
  return renderXyzTile(archive, image, z, x, y, uniforms.format(), uniforms.jpegQuality());
}

Result<Picture> exportDziTile(const Archive& archive, uint32_t image, uint32_t dz_level,
                              uint32_t col, uint32_t row, UniformPictures& uniforms) {
  const ImageInfo& info = archive.images()[image];
  if (const std::optional<DziStoredTile> stored = dziStoredTile(info, image, dz_level, col, row)) {
    TESSERA_ASSIGN_OR_RETURN(TileEntry entry, archive.tileEntry(stored->tile));
    if (const std::optional<UniformTexel> texel = uniformTexel(info, entry)) {
      TESSERA_ASSIGN_OR_RETURN(const Picture* picture,
                               uniforms.dzi(*texel, stored->width_px, stored->height_px));
      return *picture;
    }
  }
  return renderDziTile(archive, image, dz_level, col, row, uniforms.format(),
                       uniforms.jpegQuality());
}

}  // namespace tessera::detail
