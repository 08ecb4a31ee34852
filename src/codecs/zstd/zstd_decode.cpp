#include "zstd/zstd.h"

#include <fmt/format.h>
#include <zstd.h>

#include "codec_internal.h"
#include "codecs/decode.h"
#include "zstd/zstd_frame.h"

namespace tessera::detail {

namespace {

// Frames we write are single-segment (content size known, window = content), so a decoder
// never needs a window larger than one tile: 2080 x 2080 x 4 bytes < 2^25. A hostile frame that
// asks for more is refused instead of allocating up to zstd's default limit of 2^27.
constexpr int kMaxWindowLog = 25;

struct ZstdDecodeState : CodecState {
  ZstdFrameDecoder frame;
};

// The header checks made before touching the data: the declared size must be the expected one
// and the frame must end exactly where the payload does.
Result<void> checkFrameHeader(std::span<const uint8_t> frame, size_t expected_bytes,
                              const char* what) {
  unsigned long long content_bytes = ZSTD_getFrameContentSize(frame.data(), frame.size());
  if (content_bytes == ZSTD_CONTENTSIZE_ERROR)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: not a zstd frame ({} bytes)", what, frame.size()));
  if (content_bytes == ZSTD_CONTENTSIZE_UNKNOWN)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: zstd frame does not record its size", what));
  if (content_bytes != expected_bytes)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: zstd frame holds {} bytes, {} expected", what,
                                                 content_bytes, expected_bytes));
  size_t frame_bytes = ZSTD_findFrameCompressedSize(frame.data(), frame.size());
  if (ZSTD_isError(frame_bytes))
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: truncated zstd frame: {}", what, ZSTD_getErrorName(frame_bytes)));
  if (frame_bytes != frame.size())
    return fail(ErrorCode::kCorrupt, fmt::format("{}: {} trailing bytes after the zstd frame", what,
                                                 frame.size() - frame_bytes));
  return {};
}

}  // namespace

Result<void> decompressZstdFrame(std::span<const uint8_t> frame, std::span<uint8_t> out,
                                 const char* what, ZstdFrameDecoder& decoder) {
  TESSERA_TRY(checkFrameHeader(frame, out.size(), what));
  if (decoder.context == nullptr) {
    decoder.context = ZSTD_createDCtx();
    if (decoder.context == nullptr)
      return fail(ErrorCode::kInternal, fmt::format("{}: cannot create a zstd context", what));
    ZSTD_DCtx_setParameter(decoder.context, ZSTD_d_windowLogMax, kMaxWindowLog);
  }
  size_t written =
      ZSTD_decompressDCtx(decoder.context, out.data(), out.size(), frame.data(), frame.size());
  if (ZSTD_isError(written))
    return fail(ErrorCode::kCorrupt, fmt::format("{}: zstd: {}", what, ZSTD_getErrorName(written)));
  if (written != out.size())
    return fail(ErrorCode::kCorrupt, fmt::format("{}: zstd frame decoded to {} bytes, {} expected",
                                                 what, written, out.size()));
  return {};
}

bool isWholeZstdFrame(std::span<const uint8_t> payload, size_t content_bytes) {
  return checkFrameHeader(payload, content_bytes, "zstd payload").has_value();
}

Result<void> decodeZstd(std::span<const uint8_t> payload, Image& out,
                        const ParentTexels* /*parent*/, CodecScratch* scratch) {
  ScratchRef ref(scratch);
  auto& state = ref.state<ZstdDecodeState>(Codec::kZstd, CodecSide::kDecode);
  return decompressZstdFrame(payload, out.texels, "zstd payload", state.frame);
}

}  // namespace tessera::detail
