#include "uniform_pictures.h"

namespace tessera::detail {

Result<const Picture*> UniformPictures::xyz(UniformTexel texel) {
  if (auto found = xyz_.find(texel.rgba); found != xyz_.end()) return &found->second;
  TESSERA_ASSIGN_OR_RETURN(Picture picture,
                           uniformXyzPicture(info_, texel, format_, jpeg_quality_));
  return &xyz_.emplace(texel.rgba, std::move(picture)).first->second;
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

}  // namespace tessera::detail
