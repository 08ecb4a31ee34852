#pragma once
/// \file
/// The backend-neutral renderer: what draws views of one image from the tiles `TileStreamer`
/// hands over. A renderer mirrors the streamer's residency and never decides policy: each
/// frame it takes the uploads and releases of a `FrameUpdate`, answers with the tiles it
/// accepted and declined (`ApplyResult`, which the caller gives back to
/// `TileStreamer::acknowledge`), and draws what it holds by the sampling rules of
/// tessera/render.h (docs/rendering.md).
///
/// Backends are the rows of one table, `RendererKind` to the function that creates it (as
/// bgfx's renderer table, checked by a static_assert); the OpenGL renderers (tessera/gl.h,
/// library tessera::gl) are its first rows. A typical frame, on the render thread:
///
///     const FrameUpdate& update = streamer.update(view);
///     streamer.acknowledge(renderer.apply(update));
///     renderer.draw(view);

#include <cstdint>
#include <memory>
#include <optional>
#include <string_view>

#include <tessera/display_window.h>
#include <tessera/format.h>
#include <tessera/render.h>
#include <tessera/result.h>
#include <tessera/stream.h>
#include <tessera/view.h>

namespace tessera {

/// The rows of the backend table, in its order; `kCount` is its size.
enum class RendererKind : uint8_t {
  /// OpenGL 4.5 (Backes et al., section 7): one quad per resident tile, coarse levels first
  /// and finer ones over them, tiles in a texture array.
  kTileQuads,
  /// OpenGL 4.5 (Luo & Duan, sections 3.3 and 3.5): one texture-array layer per clip level,
  /// updated toroidally, the level chosen per fragment from screen-space derivatives.
  kClipmap,
  kCount,
};

/// The name tools take for `kind` ("tile-quads", "clipmap"); "unknown" outside the table.
/// Thread-safe.
const char* rendererName(RendererKind kind);
/// The kind `rendererName` calls `name`, or nullopt. Thread-safe.
std::optional<RendererKind> rendererNamed(std::string_view name);

/// What a renderer did in its last `apply` and `draw`.
struct RenderStats {
  uint32_t uploads = 0;         ///< tiles uploaded by the last apply
  uint64_t upload_bytes = 0;    ///< their texel bytes
  uint32_t declined = 0;        ///< tiles the last apply declined
  uint32_t resident_tiles = 0;  ///< tiles the renderer holds now
  uint32_t tiles_drawn = 0;     ///< tiles (quads) the last draw drew, after culling
  uint64_t gpu_bytes = 0;       ///< texture memory allocated for tiles
  /// Texture and buffer storage allocated since creation: the tile array or clip layers
  /// (each growth or reallocation), the staging ring and the colour target (each new size).
  /// Sized up front (RendererOptions), a flight at one viewport adds none after its first
  /// draw: a frame that allocates stalls the render thread (docs/rendering.md, "Uploads").
  uint32_t storage_allocations = 0;
  double apply_cpu_ms = 0;  ///< render-thread time of the last apply
  double draw_cpu_ms = 0;   ///< render-thread time of the last draw (commands issued)
};

/// Sizes a renderer starts with, allocated by createRenderer; each grows on demand. A caller
/// that knows its viewport sizes them so that no frame allocates: `initial_layers` from
/// residentTilesBound (tessera/stream.h), `initial_clip_tiles` from clipRegionTiles.
struct RendererOptions {
  /// Tile quads: tile layers allocated at first; the array grows by doubling up to the
  /// driver's limit.
  uint32_t initial_layers = 64;
  /// Clipmap: tiles along a level layer's side at first (n of Backes et al., eq. 3); a frame
  /// whose clip regions are larger reallocates the layers. 0: the first frame's size,
  /// allocated at that frame.
  uint32_t initial_clip_tiles = 0;
  /// Bytes of the persistently mapped staging ring uploads go through (OpenGL 4.4 buffer
  /// storage; docs/rendering.md, "Uploads"): two frames at the largest adaptive upload
  /// budget. A frame that finds no room in it uploads less and declines the rest, offered
  /// again later, instead of waiting for the GPU. 0, or a driver without buffer storage: a
  /// staging buffer orphaned each frame, with no limit.
  size_t staging_ring_bytes = size_t(64) << 20;
  /// Tile quads: the streamer transcodes this image's JPEG tiles to bc1
  /// (StreamerOptions::transcode_to_bc1), so an image whose default codec is JPEG, 8-bit grey
  /// or RGB, is drawn from a bc1 block array as a bc1 archive is (`takesStoredBlocks()`
  /// true). Set before creation: the arrays are sized by it. The clipmap and the view
  /// renderers ignore it and keep RGBA texels.
  bool transcode_to_bc1 = false;
};

/// Draws views of one image. Render thread only: the thread on which its backend's context
/// (for the GL rows, a `GlContext`) is current, for its whole life, destruction included.
class Renderer {
 public:
  virtual ~Renderer() = default;

  /// Applies a frame: drops `update.releases` and takes `update.uploads` (the GL backends
  /// copy them all into one staging buffer, then update one texture region per tile). Returns
  /// which uploads it accepted and which it declined (no room, or not this image's tiles),
  /// and the resident tiles it dropped on its own; valid until the next apply. Never waits
  /// for the streamer, and never calls it.
  [[nodiscard]] virtual const ApplyResult& apply(const FrameUpdate& update) = 0;
  /// Draws `view` into the renderer's own colour target, at the view's viewport size.
  virtual void draw(const View& view) = 0;
  /// The last drawn picture, read back (waits for the GPU to finish drawing it).
  virtual Picture readPixels() = 0;
  /// Copies the last drawn picture to the window's back buffer, scaled to its size.
  virtual void present(uint32_t window_width, uint32_t window_height) = 0;
  /// True when the renderer holds `tile`.
  virtual bool resident(const TileId& tile) const = 0;
  virtual const RenderStats& stats() const = 0;
  virtual RendererKind kind() const = 0;
  /// Sets the window/level the next draws map samples with (tessera/display_window.h); a
  /// renderer starts with `fullRangeWindow` of the image's sample type, which draws 8-bit
  /// images as stored. Cheap: uniforms only, no tile is uploaded again.
  virtual void setDisplayWindow(const DisplayWindow& window) = 0;
  virtual const DisplayWindow& displayWindow() const = 0;
  /// True when the renderer uploads this image's bc1/bc7 tiles as stored, into block-compressed
  /// textures: the caller then sets `StreamerOptions::keep_block_compressed` so that the
  /// loaders skip the CPU decode. False for other codecs, for a context without the formats,
  /// and for renderers that take decoded texels only (docs/rendering.md).
  virtual bool takesStoredBlocks() const { return false; }
};

/// Creates the renderer of row `kind` for image `info` (1-4 channels of u8, u16 or f32, any
/// border; wide samples are uploaded as they are and windowed in the shader), for
/// views of that image only. The GL rows need a current `GlContext`, and are defined by
/// tessera::gl, which holds the table. Fails (kInvalidArgument) for a kind outside the table
/// or an image no renderer can hold, or with the backend's error (kUnsupported: no OpenGL
/// 4.5; kTooLarge: no GPU memory for the first tiles).
[[nodiscard]] Result<std::unique_ptr<Renderer>> createRenderer(RendererKind kind,
                                                               const ImageInfo& info,
                                                               const RendererOptions& options = {});

}  // namespace tessera
