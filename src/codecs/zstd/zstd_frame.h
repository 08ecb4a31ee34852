#pragma once
// One zstd frame with its content size: the zstd codec's payload, and the alpha plane of the
// JPEG codec and ptm's zstd coder. The decompressor is in the decode library, the compressor
// in the encode library.

#include <cstdint>
#include <span>
#include <vector>

#include <tessera/result.h>

struct ZSTD_CCtx_s;
struct ZSTD_DCtx_s;

namespace tessera::detail {

/// A reusable decompression context, created on first use. Owned by one thread.
struct ZstdFrameDecoder {
  ZstdFrameDecoder() = default;
  ~ZstdFrameDecoder();
  ZstdFrameDecoder(const ZstdFrameDecoder&) = delete;
  ZstdFrameDecoder& operator=(const ZstdFrameDecoder&) = delete;
  ZSTD_DCtx_s* context = nullptr;
};

/// A reusable compression context and output buffer, created on first use. Owned by one thread.
struct ZstdFrameEncoder {
  ZstdFrameEncoder() = default;
  ~ZstdFrameEncoder();
  ZstdFrameEncoder(const ZstdFrameEncoder&) = delete;
  ZstdFrameEncoder& operator=(const ZstdFrameEncoder&) = delete;
  ZSTD_CCtx_s* context = nullptr;
  std::vector<uint8_t> compressed;  ///< the frame before it is copied out
};

/// Compresses `bytes` into one zstd frame that records its content size.
Result<std::vector<uint8_t>> compressZstdFrame(std::span<const uint8_t> bytes, int level,
                                               const char* what, ZstdFrameEncoder& encoder);
/// Decompresses a payload that must be exactly one zstd frame whose content size is
/// `out.size()`. `what` names the payload in errors ("zstd payload", "jpeg alpha plane").
Result<void> decompressZstdFrame(std::span<const uint8_t> frame, std::span<uint8_t> out,
                                 const char* what, ZstdFrameDecoder& decoder);

}  // namespace tessera::detail
