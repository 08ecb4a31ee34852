#pragma once
// The layout of a bc1/bc7 payload (docs/codecs.md, "bc1 (8) and bc7 (9)"): the stored tile's
// 4x4 blocks in row-major block order, the tile padded to a multiple of 4. Shared by the
// codecs, the loader that checks and transcodes payloads, and the renderers that size layers.

#include <cstddef>
#include <cstdint>

#include <tessera/format.h>

namespace tessera::detail {

inline constexpr uint32_t kBcBlockSidePx = 4;
/// Bytes of one 4x4 block: 8 for BC1, 16 for BC7.
constexpr size_t bcBlockBytes(Codec codec) {
  return codec == Codec::kBc1 ? 8 : 16;
}
/// Blocks along a side of `side_px` texels (the padded side over 4).
constexpr uint32_t bcBlocksAlong(uint32_t side_px) {
  return (side_px + kBcBlockSidePx - 1) / kBcBlockSidePx;
}
/// The payload size of a `width_px` x `height_px` tile.
constexpr size_t bcPayloadBytes(Codec codec, uint32_t width_px, uint32_t height_px) {
  return size_t(bcBlocksAlong(width_px)) * bcBlocksAlong(height_px) * bcBlockBytes(codec);
}

}  // namespace tessera::detail
