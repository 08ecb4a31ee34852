#include "raw/raw.h"

#include <cstring>

#include <fmt/format.h>

#include "codec_internal.h"

namespace tessera::detail {

Result<void> decodeRaw(std::span<const uint8_t> payload, Image& out, const ParentTexels* /*parent*/,
                       CodecScratch* /*scratch*/) {
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
