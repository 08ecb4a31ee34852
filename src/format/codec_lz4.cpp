// LZ4: the packed texels as one LZ4 block (no frame: the size comes from the geometry).
#include <climits>

#include <fmt/format.h>
#include <lz4.h>

#include "codec_internal.h"

namespace tessera::detail {

Result<std::vector<uint8_t>> encodeLz4(const ImageView& tile, const EncodeOptions& /*options*/,
                                       CodecScratch* scratch) {
  ScratchRef state(scratch);
  std::span<const uint8_t> texels = packedTexels(tile, *state);
  if (texels.size() > size_t(LZ4_MAX_INPUT_SIZE))
    return fail(ErrorCode::kTooLarge,
                fmt::format("lz4 payload: {} bytes exceed the LZ4 block limit", texels.size()));
  int bound = LZ4_compressBound(int(texels.size()));
  state->compressed.resize(size_t(bound));
  int written = LZ4_compress_default(reinterpret_cast<const char*>(texels.data()),
                                     reinterpret_cast<char*>(state->compressed.data()),
                                     int(texels.size()), bound);
  if (written <= 0)
    return fail(ErrorCode::kInternal,
                fmt::format("lz4 payload: compression of {} bytes failed", texels.size()));
  return exactCopy(std::span(state->compressed.data(), size_t(written)));
}

Result<void> decodeLz4(std::span<const uint8_t> payload, Image& out, CodecScratch* /*scratch*/) {
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
