#pragma once
// Encoding a scene's textures: each texture's pyramid is built and encoded by a fixed pool of
// workers, one texture per work unit, and its payloads appended to a spool file; only the tile
// entries stay in memory. The layout pass (scene_writer) copies payloads into place.

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <tessera/format.h>
#include <tessera/result.h>

#include "output/output_file.h"
#include "scene_model.h"

namespace tessera::detail {

/// One encoded texture: entries[level][y * tilesX + x], kEncoded entries' offset_bytes are
/// spool offsets until the layout pass moves them.
struct SpooledTexture {
  ImageInfo info;  ///< name set from the source
  std::vector<std::vector<TileEntry>> entries;
  uint64_t payload_bytes = 0;
  uint64_t tiles_encoded = 0;
};

struct TextureSpoolOptions {
  uint32_t tile_size_px = 128;
  Codec codec = Codec::kJpeg;
  int quality = 85;
  int effort = 0;
  uint32_t threads = 1;
  uint32_t max_side_px = 16384;
};

/// Encodes scene.textures[order[k]] for every k into `spool`, returning them in `order`.
/// `on_done(k_done)` is called from the calling thread as textures finish. Errors name the
/// scene and the texture. Stops early when `cancel` becomes true (kCancelled).
[[nodiscard]] Result<std::vector<SpooledTexture>> spoolTextures(
    const ImportedScene& scene, const std::vector<uint32_t>& order,
    const TextureSpoolOptions& options, const TempFile& spool, uint64_t* spool_bytes,
    const std::function<void(uint64_t)>& on_done, const std::atomic<bool>* cancel);

}  // namespace tessera::detail
