// Raw: the texels themselves, row-major, channels interleaved, rows packed.
#include <cstring>

#include <fmt/format.h>

#include "codec_internal.h"

namespace tessera::detail {

Result<std::vector<uint8_t>> encodeRaw(const ImageView& tile, const EncodeOptions& /*options*/,
                                       CodecScratch* /*scratch*/) {
  const size_t row_bytes = size_t(tile.width_px) * tile.channels;
  std::vector<uint8_t> payload(row_bytes * tile.height_px);
  for (uint32_t y = 0; y < tile.height_px; ++y)
    std::memcpy(payload.data() + y * row_bytes, tile.row(y), row_bytes);
  return payload;
}

Result<void> decodeRaw(std::span<const uint8_t> payload, Image& out, CodecScratch* /*scratch*/) {
  // The size is the only structure raw has, so it is the whole check: a payload of another
  // size is truncated or padded, never reinterpreted.
  if (payload.size() != out.texels.size())
    return fail(
        ErrorCode::kCorrupt,
        fmt::format("raw payload: {} bytes, {} expected for {}", payload.size(), out.texels.size(),
                    geometryText(out.width_px, out.height_px, out.channels)));
  std::memcpy(out.texels.data(), payload.data(), payload.size());
  return {};
}

}  // namespace tessera::detail
