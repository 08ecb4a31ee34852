#include "webp/webp.h"

#include <algorithm>
#include <cstring>
#include <string_view>

#include <fmt/format.h>
#include <webp/decode.h>

#include "codec_internal.h"
#include "webp/webp_layout.h"

namespace tessera::detail {

using namespace webp;

namespace {

struct WebpDecodeState : CodecState {
  std::vector<uint8_t> rgb;  ///< gray tiles as decoded, R = G = B
};

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

}  // namespace

Result<void> decodeWebp(std::span<const uint8_t> payload, Image& out,
                        const ParentTexels* /*parent*/, CodecScratch* scratch) {
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
  ScratchRef ref(scratch);
  auto* state = &ref.state<WebpDecodeState>(Codec::kWebp, CodecSide::kDecode);
  uint8_t* decoded = out.texels.data();
  if (out.channels <= 2) {
    state->rgb.resize(size_t(width) * height * decoded_channels);
    decoded = state->rgb.data();
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
