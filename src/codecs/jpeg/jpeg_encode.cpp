#include "jpeg/jpeg.h"

#include <algorithm>
#include <cstring>

#include <fmt/format.h>
#include <turbojpeg.h>

#include "codec_internal.h"
#include "jpeg/jpeg_common.h"
#include "zstd/zstd_frame.h"

namespace tessera::detail {

using namespace jpeg;

namespace {

// Opaque alpha planes shrink to a dozen bytes at any level; level 1 keeps the encoder fast
// on real masks, where higher levels gain little.
constexpr int kAlphaZstdLevel = 1;
// ISLOW DCT, the libjpeg default that libvips also uses.
constexpr int kCompressFlags = TJFLAG_ACCURATEDCT | TJFLAG_NOREALLOC;

struct JpegEncodeState : CodecState {
  ~JpegEncodeState() override {
    if (compressor != nullptr) tjDestroy(compressor);
    tjFree(jpeg_buffer);
  }
  void* compressor = nullptr;  ///< tjhandle from tjInitCompress
  /// A buffer of tjBufSize() bytes that TurboJPEG compresses into without reallocating;
  /// allocated with tjAlloc, `jpeg_buffer_bytes` long.
  uint8_t* jpeg_buffer = nullptr;
  size_t jpeg_buffer_bytes = 0;
  std::vector<uint8_t> gray;   ///< gray+alpha: the gray plane split out
  std::vector<uint8_t> plane;  ///< the alpha plane
  ZstdFrameEncoder alpha;
};

Result<tjhandle> compressor(JpegEncodeState& state) {
  if (state.compressor == nullptr) state.compressor = tjInitCompress();
  if (state.compressor == nullptr)
    return fail(ErrorCode::kInternal, fmt::format("{}: cannot create a TurboJPEG compressor: {}",
                                                  kWhat, tjGetErrorStr2(nullptr)));
  return static_cast<tjhandle>(state.compressor);
}

}  // namespace

Result<std::vector<uint8_t>> encodeJpeg(const ImageView& tile, const EncodeOptions& options,
                                        const ParentTexels* /*parent*/, CodecScratch* scratch) {
  if (tile.width_px > kMaxJpegSidePx || tile.height_px > kMaxJpegSidePx)
    return fail(ErrorCode::kTooLarge, fmt::format("{}: {}x{} exceeds JPEG's {} px limit", kWhat,
                                                  tile.width_px, tile.height_px, kMaxJpegSidePx));
  ScratchRef ref(scratch);
  auto* state = &ref.state<JpegEncodeState>(Codec::kJpeg, CodecSide::kEncode);
  TESSERA_ASSIGN_OR_RETURN(tjhandle handle, compressor(*state));
  const uint32_t width = tile.width_px;
  const uint32_t height = tile.height_px;
  const size_t plane_bytes = size_t(width) * height;

  // Colour channels go to TurboJPEG straight from the caller's rows where its pixel formats
  // allow (RGBX skips the alpha byte); gray+alpha needs its gray plane split out first.
  const uint8_t* colour = tile.data;
  size_t colour_stride = tile.stride_bytes;
  int pixel_format = TJPF_GRAY;
  int subsampling = TJSAMP_GRAY;
  if (tile.channels >= 3) {
    pixel_format = tile.channels == 3 ? TJPF_RGB : TJPF_RGBX;
    subsampling = options.chroma_subsampling ? TJSAMP_420 : TJSAMP_444;
  }
  if (hasAlpha(tile.channels)) {
    const uint32_t alpha_index = tile.channels - 1;
    state->plane.resize(plane_bytes);
    if (tile.channels == 2) state->gray.resize(plane_bytes);
    for (uint32_t y = 0; y < height; ++y) {
      const uint8_t* src = tile.row(y);
      uint8_t* alpha = state->plane.data() + size_t(y) * width;
      for (uint32_t x = 0; x < width; ++x) alpha[x] = src[x * tile.channels + alpha_index];
      if (tile.channels == 2) {
        uint8_t* gray = state->gray.data() + size_t(y) * width;
        for (uint32_t x = 0; x < width; ++x) gray[x] = src[x * 2];
      }
    }
    if (tile.channels == 2) {
      colour = state->gray.data();
      colour_stride = width;
    }
  }

  const unsigned long bound = tjBufSize(int(width), int(height), subsampling);
  if (bound == static_cast<unsigned long>(-1))
    return fail(ErrorCode::kInternal,
                fmt::format("{}: tjBufSize: {}", kWhat, tjGetErrorStr2(handle)));
  if (state->jpeg_buffer_bytes < bound) {
    tjFree(state->jpeg_buffer);
    state->jpeg_buffer = tjAlloc(int(bound));
    state->jpeg_buffer_bytes = state->jpeg_buffer != nullptr ? bound : 0;
    if (state->jpeg_buffer == nullptr)
      return fail(ErrorCode::kInternal,
                  fmt::format("{}: cannot allocate {} bytes for the JPEG", kWhat, bound));
  }
  unsigned char* jpeg = state->jpeg_buffer;
  unsigned long jpeg_bytes = state->jpeg_buffer_bytes;
  const int quality = std::clamp(options.quality, 1, 100);
  if (tjCompress2(handle, colour, int(width), int(colour_stride), int(height), pixel_format, &jpeg,
                  &jpeg_bytes, subsampling, quality, kCompressFlags) != 0) {
    Unexpected error =
        fail(ErrorCode::kInternal,
             fmt::format("{}: TurboJPEG compression of {} failed: {}", kWhat,
                         geometryText(width, height, tile.channels), tjGetErrorStr2(handle)));
    dropHandle(state->compressor);
    return error;
  }

  if (!hasAlpha(tile.channels)) return exactCopy(std::span(jpeg, jpeg_bytes));
  TESSERA_ASSIGN_OR_RETURN(
      std::vector<uint8_t> alpha,
      compressZstdFrame(state->plane, kAlphaZstdLevel, "jpeg alpha plane", state->alpha));
  std::vector<uint8_t> payload(kAlphaLengthBytes + jpeg_bytes + alpha.size());
  const uint32_t length = uint32_t(jpeg_bytes);
  for (size_t i = 0; i < kAlphaLengthBytes; ++i) payload[i] = uint8_t(length >> (8 * i));
  std::memcpy(payload.data() + kAlphaLengthBytes, jpeg, jpeg_bytes);
  std::memcpy(payload.data() + kAlphaLengthBytes + jpeg_bytes, alpha.data(), alpha.size());
  return payload;
}

}  // namespace tessera::detail
