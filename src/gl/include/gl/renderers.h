#pragma once
// Shared by the renderers: their common base and their factories.

#include <memory>
#include <optional>
#include <vector>

#include <tessera/gl.h>

#include "gl_objects.h"

namespace tessera::gl {

/// What both renderers share: the colour target a view is drawn into, read back from and
/// presented from.
class TargetRenderer : public GlRenderer {
 public:
  Picture readPixels() override;
  void present(uint32_t window_width, uint32_t window_height) override;

 protected:
  ColourTarget target_;
};

[[nodiscard]] Result<std::unique_ptr<GlRenderer>> createTileQuadsRenderer(
    const ImageInfo& info, const GlRendererOptions& options);
[[nodiscard]] Result<std::unique_ptr<GlRenderer>> createClipmapRenderer(
    const ImageInfo& info, const GlRendererOptions& options);

/// A clipmap level layer as the GPU holds it, for tests: `side` x `side` texels of the image's
/// channels, and the tile owning each of the `slots` x `slots` slots.
struct ClipmapLayer {
  uint32_t slots = 0;
  uint32_t side = 0;
  std::vector<uint8_t> texels;
  std::vector<std::optional<TileId>> owners;
};

/// Reads level `level` of a clipmap renderer back from the GPU; fails for other renderers.
[[nodiscard]] Result<ClipmapLayer> readClipmapLayer(GlRenderer& renderer, uint32_t level);

}  // namespace tessera::gl
