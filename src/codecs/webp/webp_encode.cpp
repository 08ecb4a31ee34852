#include "webp/webp.h"

#include <algorithm>
#include <cstring>
#include <string_view>

#include <fmt/format.h>
#include <webp/encode.h>

#include "codec_internal.h"
#include "webp/webp_layout.h"

namespace tessera::detail {

using namespace webp;

namespace {

// Lossless preset 1 by default: on image-like tiles it is several times faster than libwebp's
// default preset 6 for a few percent more bytes (docs/codecs.md).
constexpr int kDefaultWebpEffort = 1;

struct WebpEncodeState : CodecState {
  std::vector<uint8_t> rgb;  ///< gray tiles expanded to R = G = B
};

const char* encodingErrorName(WebPEncodingError error) {
  switch (error) {
    case VP8_ENC_ERROR_OUT_OF_MEMORY:
    case VP8_ENC_ERROR_BITSTREAM_OUT_OF_MEMORY: return "out of memory";
    case VP8_ENC_ERROR_BAD_DIMENSION: return "bad dimension";
    case VP8_ENC_ERROR_FILE_TOO_BIG: return "file too big";
    default: return "encoder error";
  }
}

}  // namespace

Result<std::vector<uint8_t>> encodeWebp(const ImageView& tile, const EncodeOptions& options,
                                        const ParentTexels* /*parent*/, CodecScratch* scratch) {
  if (tile.width_px > WEBP_MAX_DIMENSION || tile.height_px > WEBP_MAX_DIMENSION)
    return fail(ErrorCode::kTooLarge,
                fmt::format("{}: {}x{} exceeds WebP's {} px limit", kWhat, tile.width_px,
                            tile.height_px, WEBP_MAX_DIMENSION));
  ScratchRef ref(scratch);
  auto* state = &ref.state<WebpEncodeState>(Codec::kWebp, CodecSide::kEncode);
  const uint32_t width = tile.width_px;
  const uint32_t height = tile.height_px;
  const bool alpha = tile.channels == 2 || tile.channels == 4;
  const uint8_t* texels = tile.data;
  size_t stride = tile.stride_bytes;
  if (tile.channels <= 2) {
    // Gray is expanded to R = G = B; VP8L's subtract-green transform codes the copies in a
    // few bits per image, not per pixel.
    const uint32_t out_channels = alpha ? 4 : 3;
    state->rgb.resize(size_t(width) * height * out_channels);
    for (uint32_t y = 0; y < height; ++y) {
      const uint8_t* src = tile.row(y);
      uint8_t* dst = state->rgb.data() + size_t(y) * width * out_channels;
      for (uint32_t x = 0; x < width; ++x) {
        const uint8_t gray = src[x * tile.channels];
        dst[0] = dst[1] = dst[2] = gray;
        if (alpha) dst[3] = src[x * 2 + 1];
        dst += out_channels;
      }
    }
    texels = state->rgb.data();
    stride = size_t(width) * out_channels;
  }

  WebPConfig config;
  const int effort = std::clamp(options.effort != 0 ? options.effort : kDefaultWebpEffort, 0, 9);
  if (!WebPConfigInit(&config) || !WebPConfigLosslessPreset(&config, effort))
    return fail(ErrorCode::kInternal, fmt::format("{}: libwebp version mismatch", kWhat));
  // Keep RGB under fully transparent alpha: without it libwebp rewrites those texels and the
  // codec would not be lossless.
  config.exact = 1;
  WebPPicture picture;
  if (!WebPPictureInit(&picture))
    return fail(ErrorCode::kInternal, fmt::format("{}: libwebp version mismatch", kWhat));
  picture.use_argb = 1;
  picture.width = int(width);
  picture.height = int(height);
  WebPMemoryWriter writer;
  WebPMemoryWriterInit(&writer);
  picture.writer = WebPMemoryWrite;
  picture.custom_ptr = &writer;
  const int imported = alpha ? WebPPictureImportRGBA(&picture, texels, int(stride))
                             : WebPPictureImportRGB(&picture, texels, int(stride));
  const bool encoded = imported && WebPEncode(&config, &picture);
  const WebPEncodingError error = picture.error_code;
  WebPPictureFree(&picture);
  if (!encoded) {
    WebPMemoryWriterClear(&writer);
    return fail(ErrorCode::kInternal,
                fmt::format("{}: libwebp failed to encode {}: {}", kWhat,
                            geometryText(width, height, tile.channels),
                            imported ? encodingErrorName(error) : "import failed"));
  }
  std::vector<uint8_t> payload = exactCopy(std::span(writer.mem, writer.size));
  WebPMemoryWriterClear(&writer);
  // libwebp clears the VP8L alpha_is_used hint when every texel is opaque, which would make
  // an opaque RGBA payload indistinguishable from an RGB one. Setting it back (the VP8L spec
  // says decoders treat it as a hint only) lets decode check the channel count exactly.
  if (alpha) {
    if (payload.size() <= kAlphaHintByte || std::memcmp(payload.data() + 12, "VP8L", 4) != 0 ||
        payload[kRiffHeaderBytes + kChunkHeaderBytes] != kVp8lSignature)
      return fail(ErrorCode::kInternal,
                  fmt::format("{}: libwebp did not write a simple VP8L file", kWhat));
    payload[kAlphaHintByte] |= kAlphaHintBit;
  }
  return payload;
}

}  // namespace tessera::detail
