#pragma once
/// \file
/// Drawing a streamed scene (docs/scenes.md, "Rendering"; issue 28, item 7): a perspective
/// OpenGL 4.5 renderer of the objects a SceneStreamer can draw, each with its mesh and its
/// base-colour texture. A texture's GL storage holds its whole mip chain from the start and
/// levels are uploaded as the streamer makes them resident; sampling is clamped to the
/// uploaded levels (GL_TEXTURE_BASE_LEVEL and GL_TEXTURE_MIN_LOD), so a texture refines in
/// place and never shows a level that has not arrived. The world is right-handed (glTF's):
/// screen x runs along -cameraBasis().right, screen y along up (the basis is mirrored, up =
/// forward x right), so a y-up scene shows upright with the roll `tessera fly` gives it.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <tessera/render.h>
#include <tessera/result.h>
#include <tessera/scene.h>
#include <tessera/scene_stream.h>
#include <tessera/view.h>

namespace tessera {

/// Settings of a SceneRenderer.
struct SceneRenderOptions {
  /// Texel bytes of finer-than-coarsest levels uploaded per frame at most (the first level of
  /// a frame always goes, so a level larger than the budget still arrives). Coarsest levels
  /// and meshes are uploaded when first drawn, outside the budget: an object is never drawn
  /// without them.
  uint64_t upload_budget_bytes = 8ull << 20;
  /// The reference: every texture drawn is read and decoded whole (every level) from the
  /// archive, synchronously, the first time it is drawn. The streamer then only says which
  /// objects to draw. Blocks on the archive: for tests and tools, never a render loop.
  bool all_levels_resident = false;
  /// For tests: every level of a new texture is first cleared to this colour (R in the low
  /// byte), so a sample of a level that never arrived shows it.
  std::optional<uint32_t> unloaded_level_rgba;
  uint32_t background_rgba = 0xFF000000u;  ///< cleared to before drawing; opaque black
};

/// An axis-aligned box drawn as lines over the scene (R-tree nodes; the view cell of coverage
/// hints).
struct OverlayBox {
  Box3 box;
  uint32_t rgba = 0xFF00FFFFu;  ///< R in the low byte
};

/// What draw shows beside the scene (`tessera view`'s overlays).
struct SceneOverlays {
  /// Tints each object by the level its base-colour texture is sampled from (the colours of
  /// sceneLevelTint).
  bool level_tint = false;
  std::vector<OverlayBox> boxes;
};

/// The colour of `level` in the level tint: level 0 green through yellow and red to purple.
uint32_t sceneLevelTint(uint32_t level);

/// What one draw did.
struct SceneDrawStats {
  uint32_t objects_drawn = 0;
  /// Drawn objects with a base-colour texture of which no level is on the GPU: always 0 (the
  /// coarsest level is uploaded before its first draw).
  uint32_t untextured_objects = 0;
  /// Textures drawn whose sampled level is coarser than the streamer wants: the picture is
  /// not at full quality yet.
  uint32_t textures_below_wanted = 0;
  uint32_t levels_uploaded = 0;  ///< levels finer than the coarsest uploaded this frame
  uint64_t bytes_uploaded = 0;   ///< texel bytes uploaded this frame (coarsest levels included)
  uint32_t meshes_uploaded = 0;
  uint64_t sampled_texel_bytes = 0;  ///< texels of every sampled level on the GPU, 4 bytes each
  double render_ms = 0;              ///< render-thread time of the draw (uploads included)
};

/// Draws a scene streamed by a SceneStreamer. Render thread only, with a current OpenGL 4.5
/// context (GlContext) that outlives the renderer.
class SceneRenderer {
 public:
  /// Reads the texture table (cached by the archive after SceneStreamer::open) and links the
  /// programs. Fails naming the archive (table) or the driver's log (programs).
  [[nodiscard]] static Result<std::unique_ptr<SceneRenderer>> create(
      std::shared_ptr<const SceneArchive> archive, const SceneRenderOptions& options = {});
  ~SceneRenderer();
  SceneRenderer(const SceneRenderer&) = delete;
  SceneRenderer& operator=(const SceneRenderer&) = delete;

  /// Uploads what the frame needs (meshes and coarsest levels of newly drawn objects, then
  /// finer resident levels within the budget), mirrors evictions by raising a texture's base
  /// level, and draws streamer.drawableObjects() seen by `camera` with a depth test into a
  /// target of the camera's viewport size. Never waits on the streamer's workers. With
  /// all_levels_resident, the first draw of a texture reads it whole (blocking); the objects
  /// of a texture that fails to read are not drawn (untextured_objects counts them), and
  /// readFailures and firstReadError say why.
  SceneDrawStats draw(const SceneStreamer& streamer, const PerspectiveView& camera,
                      const SceneOverlays& overlays = {});
  /// The last draw's picture, rows top to bottom.
  Picture readPixels();
  /// Blits the last draw to the current window's framebuffer, scaled.
  void present(uint32_t window_width, uint32_t window_height);

  /// The finest level of `texture` sampled: GL_TEXTURE_BASE_LEVEL; its level count when none
  /// is on the GPU yet.
  uint32_t sampledLevel(uint32_t texture) const;
  /// all_levels_resident: reads of whole textures that failed; else 0.
  uint32_t readFailures() const;
  /// The first of those failures' messages (naming the archive and the tile), or "".
  const std::string& firstReadError() const;

  struct Impl;

 private:
  explicit SceneRenderer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace tessera
