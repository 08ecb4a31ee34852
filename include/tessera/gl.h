#pragma once
/// \file
/// The OpenGL backend (OpenGL 4.5 core, loaded with libepoxy): a context, headless through EGL
/// on the surfaceless platform (Mesa llvmpipe in CI, no display) or windowed through GLFW, and
/// the renderers that draw a view from the tiles `TileStreamer` hands them. The backend
/// mirrors the streamer's residency and never decides policy: it uploads what a frame lists,
/// drops what it releases, and draws what is resident by the sampling rules of
/// `tessera/render.h` (docs/rendering.md).

#include <cstdint>
#include <memory>
#include <string>

#include <tessera/render.h>
#include <tessera/result.h>
#include <tessera/stream.h>

struct GLFWwindow;

namespace tessera {

/// An OpenGL 4.5 core context, current on the thread that created it.
class GlContext {
 public:
  /// A context with no window or display: EGL's surfaceless platform (Mesa). Renderers draw
  /// into framebuffers of their own. Fails naming what is missing (no EGL, no driver, no 4.5).
  [[nodiscard]] static Result<std::unique_ptr<GlContext>> createHeadless();
  /// A window through GLFW with its context current. Fails when there is no display (the
  /// message says so and points to the headless `tessera fly`).
  [[nodiscard]] static Result<std::unique_ptr<GlContext>> createWindow(uint32_t width,
                                                                       uint32_t height,
                                                                       const std::string& title);
  ~GlContext();
  GlContext(const GlContext&) = delete;
  GlContext& operator=(const GlContext&) = delete;

  /// Makes this context current on the calling thread.
  void makeCurrent();
  /// GL_RENDERER and GL_VERSION, e.g. "llvmpipe (LLVM 15.0.6, 256 bits), 4.5 (Core Profile)".
  std::string description() const;
  /// The window, or null for a headless context.
  GLFWwindow* window() const;

  struct Impl;

 private:
  explicit GlContext(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// Which renderer draws the tiles.
enum class RendererKind {
  /// Backes et al., section 7: one quad per resident tile, coarse levels first and finer
  /// ones over them, tiles in a texture array.
  kTileQuads,
  /// Luo & Duan, sections 3.3 and 3.5: one texture-array layer per clip level, updated
  /// toroidally, the level chosen per fragment from screen-space derivatives.
  kClipmap,
};

/// "tile-quads" or "clipmap".
const char* rendererName(RendererKind kind);

/// What a renderer did in its last `apply` and `draw`.
struct RenderStats {
  uint32_t uploads = 0;         ///< tiles uploaded by the last apply
  uint64_t upload_bytes = 0;    ///< their texel bytes
  uint32_t declined = 0;        ///< tiles the last apply had no room for
  uint32_t resident_tiles = 0;  ///< tiles on the GPU now
  uint32_t tiles_drawn = 0;     ///< tiles (quads) the last draw drew, after FOV culling
  uint64_t gpu_bytes = 0;       ///< texture memory allocated for tiles
  double apply_cpu_ms = 0;      ///< render-thread time of the last apply
  double draw_cpu_ms = 0;       ///< render-thread time of the last draw (commands issued)
};

struct GlRendererOptions {
  /// Tile-quads: tile layers allocated at first; the array grows by doubling up to the
  /// driver's limit.
  uint32_t initial_layers = 64;
  /// Clipmap: tiles along a level layer's side at first (n of Backes et al., eq. 3); a frame
  /// whose clip regions are larger reallocates the layers.
  uint32_t initial_clip_tiles = 0;
};

/// Draws views of one image of an archive. Render thread only, with its context current.
class GlRenderer {
 public:
  /// Creates a renderer for image `info` (any channel count 1-4, any border).
  [[nodiscard]] static Result<std::unique_ptr<GlRenderer>> create(
      RendererKind kind, const ImageInfo& info, const GlRendererOptions& options = {});
  virtual ~GlRenderer() = default;

  /// Applies a frame: uploads `update.uploads` (one pixel-buffer copy, then one texture
  /// update per tile) and calls `streamer.uploaded` for each; drops `update.releases`. A tile
  /// it has no room for is handed back with `streamer.declined` and offered again later.
  virtual void apply(const FrameUpdate& update, TileStreamer& streamer) = 0;
  /// Draws `view` into the renderer's framebuffer (the view's viewport size) and leaves it
  /// bound for reading. Never waits for the streamer.
  virtual void draw(const View& view) = 0;
  /// The last drawn picture, read back from the GPU (waits for it to finish drawing).
  virtual Picture readPixels() = 0;
  /// Copies the last drawn picture to the default framebuffer (a window's back buffer).
  virtual void present(uint32_t window_width, uint32_t window_height) = 0;
  /// True when `tile` is on the GPU.
  virtual bool resident(const TileId& tile) const = 0;
  virtual const RenderStats& stats() const = 0;
  virtual RendererKind kind() const = 0;
};

}  // namespace tessera
