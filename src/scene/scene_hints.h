#pragma once
// Average coverage hints at run time (Marvie & Bouatouch, seed 003 part II; docs/scenes.md,
// "Coverage hints"): the hints of the cell the camera is in, turned into screen pixels at the
// camera's pixel density, per texture and per node, so the streamer ranks reads and texture
// loads and sizes levels before per-frame projected-size feedback exists. Policy only: no
// I/O. Owned by one thread (the streamer's render thread).

#include <cstdint>
#include <memory>
#include <vector>

#include <tessera/coverage_hints.h>
#include <tessera/scene.h>
#include <tessera/view.h>

namespace tessera::detail {

class CellHints {
 public:
  /// `texture_node[t]`: the node storing texture t; `node_count`: nodes in the tree.
  CellHints(std::shared_ptr<const CoverageHints> hints, std::vector<uint32_t> texture_node,
            uint32_t node_count);

  /// Moves to the camera's cell (recomputing only when the cell or the pixel density changes);
  /// false when the camera is more than a cell outside the grid: then there are no hints.
  bool setCamera(const PerspectiveView& camera);
  bool active() const { return cell_ >= 0; }

  /// Pixels the texture's objects cover around the camera by the hint: its share of the
  /// sampled sphere times the sphere's pixels at the camera's pixel density (4 pi /
  /// pixelAngle^2). 0 when the cell did not see it.
  double pixels(uint32_t texture) const { return pixels_[texture]; }
  /// What one sampled face pixel of the cell stands for at the camera's density: the smallest
  /// non-zero hint. A texture the cell never saw ranks below it.
  double floorPixels() const { return floor_pixels_; }
  /// The hint pixels of the textures stored at `node`.
  double nodePixels(uint32_t node) const { return node_pixels_[node]; }
  /// The textures the cell saw, in increasing order.
  const std::vector<uint32_t>& textures() const { return textures_; }
  /// Their hint pixels summed.
  double totalPixels() const { return total_pixels_; }

 private:
  std::shared_ptr<const CoverageHints> hints_;
  std::vector<uint32_t> texture_node_;
  std::vector<double> pixels_;
  std::vector<double> node_pixels_;
  std::vector<uint32_t> textures_;
  double floor_pixels_ = 0;
  double total_pixels_ = 0;
  double pixel_angle_ = 0;
  int64_t cell_ = -1;
};

/// The level a texture needs when it covers `pixels` screen pixels and spans them once: the
/// level whose texel count is closest above the pixels, floor(log2(sqrt(w h / pixels)) +
/// lod_bias), clamped to its levels; the coarsest for no pixels. The hint's counterpart of
/// the projected-size estimate's rho (scene_lod.h).
uint32_t levelForPixels(const ImageInfo& texture, double pixels, double lod_bias);

}  // namespace tessera::detail
