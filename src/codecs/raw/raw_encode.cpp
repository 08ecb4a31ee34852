#include "raw/raw.h"

#include <cstring>

namespace tessera::detail {

Result<std::vector<uint8_t>> encodeRaw(const ImageView& tile, const EncodeOptions& /*options*/,
                                       const ParentTexels* /*parent*/, CodecScratch* /*scratch*/) {
  const size_t row_bytes = size_t(tile.width_px) * tile.texelBytes();
  std::vector<uint8_t> payload(row_bytes * tile.height_px);
  for (uint32_t y = 0; y < tile.height_px; ++y)
    std::memcpy(payload.data() + y * row_bytes, tile.row(y), row_bytes);
  return payload;
}

}  // namespace tessera::detail
