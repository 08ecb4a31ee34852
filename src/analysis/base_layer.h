#pragma once
// The underlying layer for masked brushes (seed 001: "slope, height"): a height image read with
// the builder's own readers (through a temporary zstd archive of it, so TIFF, BigTIFF, PNG and
// JPEG work and memory stays bounded) at the largest level no side of which exceeds 4096.

#include <cstdint>
#include <string>

#include <tessera/format.h>
#include <tessera/result.h>

namespace tessera::detail {

struct BaseLayer {
  Image height;  ///< 1 channel: the source's first channel
  uint32_t source_width_px = 0;
  uint32_t source_height_px = 0;
};

/// Fails naming `path`. `scratch_dir` holds the temporary archive, removed before returning.
[[nodiscard]] Result<BaseLayer> loadBaseLayer(const std::string& path,
                                              const std::string& scratch_dir);

}  // namespace tessera::detail
