#pragma once
// The GL rows of the backend table (renderer_table.cpp), and a clipmap's layers read back for
// tests.

#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include <tessera/renderer.h>

namespace tessera::gl {

/// Backes et al., section 7 (tile_quads.cpp). Needs a current GL 4.5 context.
[[nodiscard]] Result<std::unique_ptr<Renderer>> createTileQuadsRenderer(
    const ImageInfo& info, const RendererOptions& options);
/// Luo & Duan, sections 3.3 and 3.5 (clipmap.cpp). Needs a current GL 4.5 context.
[[nodiscard]] Result<std::unique_ptr<Renderer>> createClipmapRenderer(
    const ImageInfo& info, const RendererOptions& options);

/// A clipmap level layer as the GPU holds it, for tests: `side` x `side` texels of the image's
/// channels, and the tile owning each of the `slots` x `slots` slots.
struct ClipmapLayer {
  uint32_t slots = 0;
  uint32_t side = 0;
  std::vector<uint8_t> texels;
  std::vector<std::optional<TileId>> owners;
};

/// Reads level `level` of a clipmap renderer back from the GPU; fails for other renderers.
[[nodiscard]] Result<ClipmapLayer> readClipmapLayer(Renderer& renderer, uint32_t level);

}  // namespace tessera::gl
