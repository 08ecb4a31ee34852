// WebP lossless through libwebp: a simple-format RIFF file holding one VP8L chunk. Gray tiles
// are coded as RGB(A) with R = G = B, which VP8L's subtract-green transform makes nearly free
// (docs/codecs.md, "webp").
#include <algorithm>
#include <cstring>

#include <fmt/format.h>
#include <webp/decode.h>
#include <webp/encode.h>

#include "codec_internal.h"

namespace tessera::detail {

namespace {

constexpr const char* kWhat = "webp payload";
// Lossless preset 1 by default: on image-like tiles it is several times faster than libwebp's
// default preset 6 for a few percent more bytes (docs/codecs.md).
constexpr int kDefaultWebpEffort = 1;
// "RIFF" size "WEBP" "VP8L" size, then the VP8L bitstream.
constexpr size_t kRiffHeaderBytes = 12;
constexpr size_t kChunkHeaderBytes = 8;
// The VP8L header: signature 0x2F, then 14 bits width - 1, 14 bits height - 1, 1 bit
// alpha_is_used, 3 bits version, packed LSB first; alpha_is_used is bit 4 of its 4th byte.
constexpr uint8_t kVp8lSignature = 0x2F;
constexpr size_t kAlphaHintByte = kRiffHeaderBytes + kChunkHeaderBytes + 4;
constexpr uint8_t kAlphaHintBit = 0x10;

uint32_t readLe32(const uint8_t* p) {
  return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
}

// libwebp accepts extended (VP8X) files, lossy chunks, and ignores bytes after the RIFF
// size; the payloads we write are exactly one VP8L chunk, so anything else is rejected here.
Result<void> checkContainer(std::span<const uint8_t> payload) {
  const uint8_t* data = payload.data();
  if (payload.size() < kRiffHeaderBytes + kChunkHeaderBytes || std::memcmp(data, "RIFF", 4) != 0 ||
      std::memcmp(data + 8, "WEBP", 4) != 0)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: not a RIFF WEBP file ({} bytes)", kWhat, payload.size()));
  if (std::memcmp(data + 12, "VP8L", 4) != 0)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: first chunk is '{}', a lossless VP8L chunk expected", kWhat,
                            std::string_view(reinterpret_cast<const char*>(data + 12), 4)));
  const uint64_t riff_bytes = readLe32(data + 4);
  const uint64_t chunk_bytes = readLe32(data + 16);
  const uint64_t file_bytes =
      kRiffHeaderBytes + kChunkHeaderBytes + chunk_bytes + (chunk_bytes & 1);
  if (riff_bytes + kChunkHeaderBytes != payload.size() || file_bytes != payload.size())
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: {} bytes, but the RIFF header says {} and the VP8L chunk {}",
                            kWhat, payload.size(), riff_bytes + kChunkHeaderBytes, file_bytes));
  return {};
}

const char* statusName(VP8StatusCode status) {
  switch (status) {
    case VP8_STATUS_OK: return "ok";
    case VP8_STATUS_OUT_OF_MEMORY: return "out of memory";
    case VP8_STATUS_INVALID_PARAM: return "invalid parameter";
    case VP8_STATUS_BITSTREAM_ERROR: return "bitstream error";
    case VP8_STATUS_UNSUPPORTED_FEATURE: return "unsupported feature";
    case VP8_STATUS_SUSPENDED: return "suspended";
    case VP8_STATUS_USER_ABORT: return "aborted";
    case VP8_STATUS_NOT_ENOUGH_DATA: return "truncated";
  }
  return "unknown error";
}

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
                                        CodecScratch* scratch) {
  if (tile.width_px > WEBP_MAX_DIMENSION || tile.height_px > WEBP_MAX_DIMENSION)
    return fail(ErrorCode::kTooLarge,
                fmt::format("{}: {}x{} exceeds WebP's {} px limit", kWhat, tile.width_px,
                            tile.height_px, WEBP_MAX_DIMENSION));
  ScratchRef state(scratch);
  const uint32_t width = tile.width_px;
  const uint32_t height = tile.height_px;
  const bool alpha = tile.channels == 2 || tile.channels == 4;
  const uint8_t* texels = tile.data;
  size_t stride = tile.stride_bytes;
  if (tile.channels <= 2) {
    // Gray is expanded to R = G = B; VP8L's subtract-green transform codes the copies in a
    // few bits per image, not per pixel.
    const uint32_t out_channels = alpha ? 4 : 3;
    state->texels.resize(size_t(width) * height * out_channels);
    for (uint32_t y = 0; y < height; ++y) {
      const uint8_t* src = tile.row(y);
      uint8_t* dst = state->texels.data() + size_t(y) * width * out_channels;
      for (uint32_t x = 0; x < width; ++x) {
        const uint8_t gray = src[x * tile.channels];
        dst[0] = dst[1] = dst[2] = gray;
        if (alpha) dst[3] = src[x * 2 + 1];
        dst += out_channels;
      }
    }
    texels = state->texels.data();
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

Result<void> decodeWebp(std::span<const uint8_t> payload, Image& out, CodecScratch* scratch) {
  TESSERA_TRY(checkContainer(payload));
  WebPDecoderConfig config;
  if (!WebPInitDecoderConfig(&config))
    return fail(ErrorCode::kInternal, fmt::format("{}: libwebp version mismatch", kWhat));
  VP8StatusCode status = WebPGetFeatures(payload.data(), payload.size(), &config.input);
  if (status != VP8_STATUS_OK)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: bad WebP header: {}", kWhat, statusName(status)));
  const bool out_alpha = out.channels == 2 || out.channels == 4;
  // The encoder always sets the alpha hint for 2- and 4-channel tiles, so it tells the
  // channel count apart (gray and colour are told apart after decoding).
  const bool stream_alpha = config.input.has_alpha != 0;
  if (uint32_t(config.input.width) != out.width_px ||
      uint32_t(config.input.height) != out.height_px || stream_alpha != out_alpha)
    return geometryMismatch(kWhat, out, uint32_t(config.input.width), uint32_t(config.input.height),
                            stream_alpha ? 4 : 3);

  const uint32_t width = out.width_px;
  const uint32_t height = out.height_px;
  const uint32_t decoded_channels = out_alpha ? 4 : 3;
  ScratchRef state(scratch);
  uint8_t* decoded = out.texels.data();
  if (out.channels <= 2) {
    state->texels.resize(size_t(width) * height * decoded_channels);
    decoded = state->texels.data();
  }
  config.output.colorspace = out_alpha ? MODE_RGBA : MODE_RGB;
  config.output.is_external_memory = 1;
  config.output.u.RGBA.rgba = decoded;
  config.output.u.RGBA.stride = int(width * decoded_channels);
  config.output.u.RGBA.size = size_t(width) * height * decoded_channels;
  status = WebPDecode(payload.data(), payload.size(), &config);
  WebPFreeDecBuffer(&config.output);  // frees nothing of ours (external memory)
  if (status != VP8_STATUS_OK)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: WebP data of {}: {}", kWhat,
                            geometryText(width, height, out.channels), statusName(status)));
  if (out.channels > 2) return {};

  // Pack back to gray. A texel with R, G and B apart is not something our encoder wrote, so
  // the payload is reported corrupt rather than silently losing two channels.
  const size_t texel_count = size_t(width) * height;
  const uint8_t* src = decoded;
  uint8_t* dst = out.texels.data();
  for (size_t i = 0; i < texel_count; ++i, src += decoded_channels) {
    if (src[0] != src[1] || src[0] != src[2])
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: texel ({},{}) is not gray in a {}-channel tile", kWhat,
                              i % width, i / width, out.channels));
    *dst++ = src[0];
    if (out_alpha) *dst++ = src[3];
  }
  return {};
}

}  // namespace tessera::detail
