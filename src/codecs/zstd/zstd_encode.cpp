#include "zstd/zstd.h"

#include <algorithm>

#include <fmt/format.h>
#include <zstd.h>

#include "codec_internal.h"
#include "zstd/zstd_frame.h"

namespace tessera::detail {

namespace {

// Level 1 by default: on image-like tiles levels 2-3 save only a few percent of size but cost
// roughly a third more encode time (docs/codecs.md), and the builder encodes every tile of the
// pyramid while decode speed barely depends on the level.
constexpr int kDefaultZstdLevel = 1;

struct ZstdEncodeState : CodecState {
  ZstdFrameEncoder frame;
  std::vector<uint8_t> packed;  ///< a strided tile's texels, packed
};

}  // namespace

Result<std::vector<uint8_t>> compressZstdFrame(std::span<const uint8_t> bytes, int level,
                                               const char* what, ZstdFrameEncoder& encoder) {
  if (encoder.context == nullptr) {
    encoder.context = ZSTD_createCCtx();
    if (encoder.context == nullptr)
      return fail(ErrorCode::kInternal, fmt::format("{}: cannot create a zstd context", what));
  }
  ZSTD_CCtx* cctx = encoder.context;
  ZSTD_CCtx_reset(cctx, ZSTD_reset_session_and_parameters);
  ZSTD_CCtx_setParameter(cctx, ZSTD_c_compressionLevel, level);
  ZSTD_CCtx_setParameter(cctx, ZSTD_c_contentSizeFlag, 1);
  ZSTD_CCtx_setParameter(cctx, ZSTD_c_checksumFlag, 0);  // the archive checksums payloads
  encoder.compressed.resize(ZSTD_compressBound(bytes.size()));
  size_t written = ZSTD_compress2(cctx, encoder.compressed.data(), encoder.compressed.size(),
                                  bytes.data(), bytes.size());
  if (ZSTD_isError(written))
    return fail(ErrorCode::kInternal,
                fmt::format("{}: zstd compression failed: {}", what, ZSTD_getErrorName(written)));
  return exactCopy(std::span(encoder.compressed.data(), written));
}

Result<std::vector<uint8_t>> encodeZstd(const ImageView& tile, const EncodeOptions& options,
                                        const ParentTexels* /*parent*/, CodecScratch* scratch) {
  ScratchRef ref(scratch);
  auto& state = ref.state<ZstdEncodeState>(Codec::kZstd, CodecSide::kEncode);
  int level = options.effort != 0 ? options.effort : kDefaultZstdLevel;
  level = std::clamp(level, ZSTD_minCLevel(), ZSTD_maxCLevel());
  return compressZstdFrame(packedTexels(tile, state.packed), level, "zstd payload", state.frame);
}

}  // namespace tessera::detail
