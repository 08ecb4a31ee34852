#pragma once
// What both GL renderers share (docs/rendering.md, "The OpenGL backend"): the colour target a
// view is drawn into, read back from and presented from; the bookkeeping of an apply (the
// tiles accepted, declined and dropped, the figures of RenderStats); the staged upload of a
// frame's tiles; the program with the uniforms every renderer declares; and the GLSL their
// fragment shaders start from.

#include <chrono>
#include <functional>
#include <optional>
#include <span>

#include <tessera/renderer.h>

#include "gl/gl_objects.h"
#include "upload_ring.h"

namespace tessera::gl {

/// Levels the renderers' shaders address: the size of their per-level uniform arrays.
inline constexpr uint32_t kMaxShaderLevels = 32;

/// One tile of a frame's uploads and where it goes.
struct PendingUpload {
  const DecodedTile* tile = nullptr;  ///< null: a later tile of the same frame took its place
  uint32_t place = 0;                 ///< the renderer's layer or slot for it
};

/// The base of the GL renderers. Render thread only, with their context current.
class RendererBase : public Renderer {
 public:
  Picture readPixels() override;
  void present(uint32_t window_width, uint32_t window_height) override;
  const RenderStats& stats() const override { return stats_; }
  void setDisplayWindow(const DisplayWindow& window) override;
  const DisplayWindow& displayWindow() const override { return window_; }

 protected:
  using Clock = std::chrono::steady_clock;

  RendererBase(const ImageInfo& info, const RendererOptions& options);

  /// Links the program from the bodies of its shaders (no #version line). The fragment
  /// shader starts with the shared GLSL: MAX_LEVELS, `uniform ivec2 u_level_size[MAX_LEVELS]`
  /// (each level's width and height in texels, set here) and `float levelOfDetail(vec2
  /// world)`. The vertex shader declares `uniform mat4 u_view_projection`, which beginDraw
  /// sets. The fragment shader also has `vec4 displayColour(vec4 texel)`, the display window
  /// (tessera/display_window.h) applied to a filtered texel: each renderer's last step.
  /// The error carries the driver's log.
  [[nodiscard]] Result<void> linkRendererProgram(const char* name, const char* vertex_body,
                                                 const char* fragment_body);

  /// Starts an apply: forgets the last one's result and figures.
  void beginApply();
  /// True when this renderer can hold `tile`: this image's channels, sample type, stored tile
  /// size and levels, or, kept as blocks, block_codec_'s at the padded side. Any other tile is
  /// declined: never drawn, never a wrong tile.
  bool holds(const DecodedTile& tile) const;
  /// The stored tile side rounded up to whole 4x4 blocks: a block layer's side.
  uint32_t blockSidePx() const { return (info_.storedTileSidePx() + 3) / 4 * 4; }
  /// Records a tile of this frame's uploads as declined.
  void decline(const TileId& id);
  /// Records a tile held since an earlier frame as dropped.
  void drop(const TileId& id);
  /// Texel bytes this frame can stage (UploadRing::room: the free run of the persistently
  /// mapped ring, never waited for). A renderer declines the uploads beyond it.
  size_t stagingRoom();
  /// Copies the texels of every pending tile into the staging ring (at most stagingRoom()
  /// bytes in all), then calls `write(tile, place, offset)` for each, which updates its
  /// texture from `offset` bytes into the bound pixel-unpack buffer, and fences the span.
  /// Each written tile is accepted.
  void uploadStaged(std::span<const PendingUpload> pending,
                    const std::function<void(const DecodedTile&, uint32_t, size_t)>& write);
  /// Ends an apply begun at `started`, the renderer holding `resident_tiles` tiles now.
  const ApplyResult& endApply(Clock::time_point started, size_t resident_tiles);

  /// Binds the colour target at the view's viewport size, clears it to transparent black,
  /// turns depth testing and blending off, and sets u_view_projection for `view`, whose
  /// projection it returns.
  ViewProjection beginDraw(const View& view);
  /// Render-thread milliseconds since `start`.
  static double msSince(Clock::time_point start);

  ImageInfo info_;
  RendererOptions options_;
  TileTexelFormat texel_format_;  ///< how this image's tiles are uploaded and held
  /// The codec (bc1, bc7) whose tiles this renderer takes as stored blocks; kRaw: none (a
  /// derived renderer sets it when it has a block texture for them).
  Codec block_codec_ = Codec::kRaw;
  Program program_;
  VertexArray vertex_array_;
  RenderStats stats_;

 private:
  ColourTarget target_;
  std::optional<UploadRing> staging_;  ///< made at construction, with the context current
  GLint view_projection_uniform_ = -1;
  /// Sets the window's uniforms of program `p` from window_.
  void uploadWindow(GLuint p) const;

  DisplayWindow window_;
  std::vector<GLuint> window_programs_;  ///< every program linked, kept alive by the renderer
  ApplyResult result_;
  std::vector<std::pair<const uint8_t*, size_t>> sources_;  ///< scratch of uploadStaged
};

}  // namespace tessera::gl
