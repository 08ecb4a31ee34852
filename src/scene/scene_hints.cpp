#include "scene_hints.h"

#include <algorithm>
#include <cmath>

namespace tessera::detail {

CellHints::CellHints(std::shared_ptr<const CoverageHints> hints, std::vector<uint32_t> texture_node,
                     uint32_t node_count)
    : hints_(std::move(hints)),
      texture_node_(std::move(texture_node)),
      pixels_(texture_node_.size(), 0),
      node_pixels_(node_count, 0) {}

bool CellHints::setCamera(const PerspectiveView& camera) {
  const double eye[3] = {camera.eye_x, camera.eye_y, camera.eye_z};
  const int64_t cell = hints_ ? hints_->cellAt(eye) : -1;
  const double pixel_angle = pixelAngle(camera);
  if (cell == cell_ && pixel_angle == pixel_angle_) return active();
  for (uint32_t t : textures_) {
    pixels_[t] = 0;
    node_pixels_[texture_node_[t]] = 0;
  }
  textures_.clear();
  total_pixels_ = 0;
  cell_ = cell;
  pixel_angle_ = pixel_angle;
  if (cell < 0) return false;
  // The whole sphere of directions in the camera's pixels: what a share of it covers.
  const double sphere_pixels = 4 * M_PI / (pixel_angle * pixel_angle);
  // One face pixel at the centre of a cube face is (2 / resolution)^2 sr of the sampled
  // 4 pi per position.
  const double face_pixel = 4.0 / (double(hints_->resolution_px) * hints_->resolution_px);
  floor_pixels_ = face_pixel / (4 * M_PI * hints_->positions_per_cell) * sphere_pixels;
  for (const CoverageHint& hint : hints_->cell(uint32_t(cell))) {
    if (hint.texture >= pixels_.size()) continue;
    const double pixels = hint.coverage() * sphere_pixels;
    pixels_[hint.texture] = pixels;
    node_pixels_[texture_node_[hint.texture]] += pixels;
    total_pixels_ += pixels;
    textures_.push_back(hint.texture);
  }
  return true;
}

uint32_t levelForPixels(const ImageInfo& texture, double pixels, double lod_bias) {
  const uint32_t coarsest = texture.level_count == 0 ? 0 : texture.level_count - 1;
  if (!(pixels > 0)) return coarsest;
  const double texels = double(texture.width_px) * texture.height_px;
  const double level = std::floor(0.5 * std::log2(texels / pixels) + lod_bias);
  if (!(level > 0)) return 0;
  return uint32_t(std::min(level, double(coarsest)));
}

}  // namespace tessera::detail
