// Zstd: the packed texels as exactly one zstd frame that records its content size.
#include <algorithm>

#include <fmt/format.h>
#include <zstd.h>

#include "codec_internal.h"

namespace tessera::detail {

namespace {

// Level 1 by default: on image-like tiles levels 2-3 save only a few percent of size but cost
// roughly a third more encode time (docs/codecs.md), and the builder encodes every tile of the
// pyramid while decode speed barely depends on the level.
constexpr int kDefaultZstdLevel = 1;

// Frames we write are single-segment (content size known, window = content), so a decoder
// never needs a window larger than one tile: 2080 x 2080 x 4 bytes < 2^25. A hostile frame that
// asks for more is refused instead of allocating up to zstd's default limit of 2^27.
constexpr int kMaxWindowLog = 25;

}  // namespace

Result<std::vector<uint8_t>> compressZstdFrame(std::span<const uint8_t> bytes, int level,
                                               const char* what, CodecScratch::State& state) {
  if (state.zstd_cctx == nullptr) {
    state.zstd_cctx = ZSTD_createCCtx();
    if (state.zstd_cctx == nullptr)
      return fail(ErrorCode::kInternal, fmt::format("{}: cannot create a zstd context", what));
  }
  ZSTD_CCtx* cctx = state.zstd_cctx;
  ZSTD_CCtx_reset(cctx, ZSTD_reset_session_and_parameters);
  ZSTD_CCtx_setParameter(cctx, ZSTD_c_compressionLevel, level);
  ZSTD_CCtx_setParameter(cctx, ZSTD_c_contentSizeFlag, 1);
  ZSTD_CCtx_setParameter(cctx, ZSTD_c_checksumFlag, 0);  // the archive checksums payloads
  state.compressed.resize(ZSTD_compressBound(bytes.size()));
  size_t written = ZSTD_compress2(cctx, state.compressed.data(), state.compressed.size(),
                                  bytes.data(), bytes.size());
  if (ZSTD_isError(written))
    return fail(ErrorCode::kInternal,
                fmt::format("{}: zstd compression failed: {}", what, ZSTD_getErrorName(written)));
  return exactCopy(std::span(state.compressed.data(), written));
}

Result<void> decompressZstdFrame(std::span<const uint8_t> frame, std::span<uint8_t> out,
                                 const char* what, CodecScratch::State& state) {
  // Read the header before touching the data: the declared size must be the expected one and
  // the frame must end exactly where the payload does.
  unsigned long long content_bytes = ZSTD_getFrameContentSize(frame.data(), frame.size());
  if (content_bytes == ZSTD_CONTENTSIZE_ERROR)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: not a zstd frame ({} bytes)", what, frame.size()));
  if (content_bytes == ZSTD_CONTENTSIZE_UNKNOWN)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: zstd frame does not record its size", what));
  if (content_bytes != out.size())
    return fail(ErrorCode::kCorrupt, fmt::format("{}: zstd frame holds {} bytes, {} expected", what,
                                                 content_bytes, out.size()));
  size_t frame_bytes = ZSTD_findFrameCompressedSize(frame.data(), frame.size());
  if (ZSTD_isError(frame_bytes))
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: truncated zstd frame: {}", what, ZSTD_getErrorName(frame_bytes)));
  if (frame_bytes != frame.size())
    return fail(ErrorCode::kCorrupt, fmt::format("{}: {} trailing bytes after the zstd frame", what,
                                                 frame.size() - frame_bytes));
  if (state.zstd_dctx == nullptr) {
    state.zstd_dctx = ZSTD_createDCtx();
    if (state.zstd_dctx == nullptr)
      return fail(ErrorCode::kInternal, fmt::format("{}: cannot create a zstd context", what));
    ZSTD_DCtx_setParameter(state.zstd_dctx, ZSTD_d_windowLogMax, kMaxWindowLog);
  }
  size_t written =
      ZSTD_decompressDCtx(state.zstd_dctx, out.data(), out.size(), frame.data(), frame.size());
  if (ZSTD_isError(written))
    return fail(ErrorCode::kCorrupt, fmt::format("{}: zstd: {}", what, ZSTD_getErrorName(written)));
  if (written != out.size())
    return fail(ErrorCode::kCorrupt, fmt::format("{}: zstd frame decoded to {} bytes, {} expected",
                                                 what, written, out.size()));
  return {};
}

Result<std::vector<uint8_t>> encodeZstd(const ImageView& tile, const EncodeOptions& options,
                                        CodecScratch* scratch) {
  ScratchRef state(scratch);
  int level = options.effort != 0 ? options.effort : kDefaultZstdLevel;
  level = std::clamp(level, ZSTD_minCLevel(), ZSTD_maxCLevel());
  return compressZstdFrame(packedTexels(tile, *state), level, "zstd payload", *state);
}

Result<void> decodeZstd(std::span<const uint8_t> payload, Image& out, CodecScratch* scratch) {
  ScratchRef state(scratch);
  return decompressZstdFrame(payload, out.texels, "zstd payload", *state);
}

}  // namespace tessera::detail
