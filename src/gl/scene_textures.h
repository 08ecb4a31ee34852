#pragma once
// The GPU mirror of a streamed scene's textures (docs/scenes.md, "Rendering"): one GL texture
// per scene texture, its whole mip chain allocated when first drawn, levels uploaded coarse to
// fine as the streamer makes them resident, and sampling clamped to the uploaded chain with
// GL_TEXTURE_BASE_LEVEL and GL_TEXTURE_MIN_LOD, so a texture refines in place.

#include <cstdint>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include <tessera/scene.h>
#include <tessera/scene_render.h>
#include <tessera/scene_stream.h>

#include "gl/gl_objects.h"

namespace tessera::gl {

/// Render thread only, with the renderer's context current.
class SceneTextureMirror {
 public:
  SceneTextureMirror(std::shared_ptr<const SceneArchive> archive, std::vector<SceneTexture> records,
                     const SceneRenderOptions& options);

  /// Starts a frame: nothing staged, the whole upload budget left.
  void beginFrame();
  /// Makes `texture` drawable: allocates its storage and stages its coarsest level the first
  /// time (outside the budget). With all_levels_resident, reads every level from the archive
  /// instead (blocking). False when the streamer has no coarsest tile for it.
  bool require(uint32_t texture, const SceneStreamer& streamer);
  /// Follows the streamer's chain: samples no finer than it holds (an eviction raises the base
  /// level), and stages the finer levels it holds, coarse to fine, within the budget.
  void refine(uint32_t texture, const SceneStreamer& streamer);
  /// Uploads what was staged (one pixel-unpack buffer) and sets the sampled levels.
  void flush(SceneDrawStats& stats);

  /// The GL texture, or 0 before require.
  GLuint handle(uint32_t texture) const;
  /// GL_TEXTURE_BASE_LEVEL: the finest level sampled; the level count when nothing is up.
  uint32_t sampledLevel(uint32_t texture) const;
  /// Texel bytes (4 per texel) of every sampled level of every texture.
  uint64_t sampledTexelBytes() const { return sampled_bytes_; }
  uint32_t readFailures() const { return read_failures_; }
  const std::string& firstReadError() const { return first_read_error_; }

 private:
  /// One texture's GPU state. Levels [sampled, level_count) are sampled; levels
  /// [uploaded, level_count) hold their data (uploaded <= sampled after an eviction).
  struct GpuTexture {
    Texture texture;
    uint32_t uploaded = 0;  ///< finest level with data; level_count: none
    uint32_t sampled = 0;   ///< GL_TEXTURE_BASE_LEVEL
    uint32_t staged = 0;    ///< finest level staged this frame (== uploaded after flush)
  };
  /// One level staged for this frame's upload: the stored tiles, row-major.
  struct StagedLevel {
    uint32_t texture = 0;
    uint32_t level = 0;
    std::vector<const Image*> tiles;
  };

  GpuTexture& allocate(uint32_t texture);
  void setSampledLevel(uint32_t texture, uint32_t level);
  /// Copies a level's tiles (stored, borders included) into the texture's level; `data(i)` is
  /// where tile i's bytes are (an offset into the bound unpack buffer, or client memory).
  void writeLevel(uint32_t texture, uint32_t level, const std::vector<const Image*>& tiles,
                  const std::vector<const uint8_t*>& data);
  uint64_t levelTexelBytes(uint32_t texture, uint32_t level) const;
  /// all_levels_resident: reads and uploads every level now; false when the read failed.
  bool loadWhole(uint32_t texture);
  Result<std::vector<std::vector<Image>>> readWhole(uint32_t texture);

  std::shared_ptr<const SceneArchive> archive_;
  std::vector<SceneTexture> records_;
  SceneRenderOptions options_;
  std::vector<GpuTexture> gpu_;  ///< by texture index; texture 0 (no name) until allocated
  std::vector<StagedLevel> staged_;
  std::vector<uint32_t> touched_;  ///< textures whose sampled level may go finer at flush
  uint64_t budget_left_bytes_ = 0;
  bool staged_finer_ = false;  ///< a finer level went this frame (the first always may)
  uint64_t sampled_bytes_ = 0;
  UploadStaging staging_;
  /// all_levels_resident: node blocks parsed so far, by node (textures share nodes).
  std::unordered_map<uint32_t, NodeContents> nodes_;
  uint32_t read_failures_ = 0;
  std::string first_read_error_;
};

}  // namespace tessera::gl
