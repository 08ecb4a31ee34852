#pragma once
// The overlays of `tessera view`, drawn over the renderer's picture in the same view
// transform: levels in colour (Backes et al., Fig. 1), the clip regions and the field of view,
// and the tile grid.

#include <memory>
#include <unordered_set>

#include <tessera/cache.h>
#include <tessera/format.h>
#include <tessera/renderer.h>
#include <tessera/result.h>
#include <tessera/stream.h>

#include "gl/gl_objects.h"

namespace tessera::cli {

struct OverlayOptions {
  bool levels = false;        ///< tint each area by the level that draws it
  bool clip_regions = false;  ///< each level's clip region, and the view's footprint in white
  bool grid = false;          ///< tile boundaries of the desired level, and the image border
  bool any() const { return levels || clip_regions || grid; }
};

/// The colour of `level` in every overlay and the panel's legend, RGBA 0..1.
struct LevelColour {
  float r, g, b;
};
LevelColour levelColour(uint32_t level);

/// Render thread only, with the viewer's context current.
class ViewOverlay {
 public:
  [[nodiscard]] static Result<std::unique_ptr<ViewOverlay>> create();

  /// Draws the chosen overlays into the framebuffer bound now (the renderer's, right after its
  /// draw), blending over it. `resident` holds the tiles the renderer holds; `update` is this
  /// frame's.
  void draw(const View& view, const ImageInfo& info, const OverlayOptions& options,
            const FrameUpdate& update, const std::unordered_set<TileId, TileIdHash>& resident,
            const Renderer& renderer);

 private:
  struct Vertex {
    float x, y;     ///< level-0 pixels relative to the view transform's anchor
    uint32_t rgba;  ///< 8 bits per channel, red in the low byte
  };
  ViewOverlay() = default;

  gl::Program program_;
  gl::VertexArray vertex_array_;
  gl::Buffer vertices_;
  int view_projection_uniform_ = -1;
  std::vector<Vertex> triangles_;  ///< scratch, reused every frame
  std::vector<Vertex> lines_;
};

}  // namespace tessera::cli
