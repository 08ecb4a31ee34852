#include "lz4/lz4.h"

#include <climits>

#include <fmt/format.h>
#include <lz4.h>

#include "codec_internal.h"

namespace tessera::detail {

Result<void> decodeLz4(std::span<const uint8_t> payload, Image& out, const ParentTexels* /*parent*/,
                       CodecScratch* /*scratch*/) {
  if (payload.empty() || payload.size() > size_t(INT_MAX) || out.texels.size() > size_t(INT_MAX))
    return fail(ErrorCode::kCorrupt,
                fmt::format("lz4 payload: {} bytes is not a valid block size", payload.size()));
  // LZ4_decompress_safe never writes past the capacity and fails unless the block's last
  // sequence ends exactly at the end of the input, so trailing bytes are rejected too.
  int written = LZ4_decompress_safe(reinterpret_cast<const char*>(payload.data()),
                                    reinterpret_cast<char*>(out.texels.data()), int(payload.size()),
                                    int(out.texels.size()));
  if (written < 0)
    return fail(ErrorCode::kCorrupt,
                fmt::format("lz4 payload: malformed block of {} bytes", payload.size()));
  if (size_t(written) != out.texels.size())
    return fail(
        ErrorCode::kCorrupt,
        fmt::format("lz4 payload: block decodes to {} bytes, {} expected for {}", written,
                    out.texels.size(), geometryText(out.width_px, out.height_px, out.channels)));
  return {};
}

}  // namespace tessera::detail
