#include "jpeg/jpeg.h"

#include <climits>
#include <cstring>

#include <fmt/format.h>
#include <turbojpeg.h>

#include "codec_internal.h"
#include "jpeg/jpeg_common.h"
#include "zstd/zstd_frame.h"

namespace tessera::detail {

using namespace jpeg;

namespace {

// ISLOW DCT, accurate to within one code value of the reference IDCT.
constexpr int kDecompressFlags = TJFLAG_ACCURATEDCT | TJFLAG_STOPONWARNING;

struct JpegDecodeState : CodecState {
  ~JpegDecodeState() override {
    if (decompressor != nullptr) tjDestroy(decompressor);
  }
  void* decompressor = nullptr;  ///< tjhandle from tjInitDecompress
  std::vector<uint8_t> gray;     ///< gray+alpha: the decoded gray plane
  std::vector<uint8_t> plane;    ///< the alpha plane
  ZstdFrameDecoder alpha;
};

struct JpegStructure {
  uint32_t width_px = 0;
  uint32_t height_px = 0;
  uint32_t components = 0;
};

uint32_t readBe16(const uint8_t* p) {
  return uint32_t(p[0]) << 8 | p[1];
}

// Walks the marker segments of `jpeg` without decoding it: SOI, segments whose lengths stay
// inside the stream, exactly one 8-bit Huffman SOF (baseline or extended sequential), at least
// one scan, and an EOI that is the stream's last two bytes. libjpeg alone would stop at EOI and
// silently ignore what follows, so this is also the trailing-bytes check.
Result<JpegStructure> walkJpeg(std::span<const uint8_t> jpeg) {
  const uint8_t* data = jpeg.data();
  const size_t size = jpeg.size();
  if (size < 4 || data[0] != 0xFF || data[1] != 0xD8)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: no JPEG start-of-image marker ({} bytes)", kWhat, size));
  JpegStructure structure;
  bool seen_frame = false;
  bool seen_scan = false;
  size_t pos = 2;
  for (;;) {
    if (pos >= size || data[pos] != 0xFF)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: expected a JPEG marker at offset {} of {}", kWhat, pos, size));
    while (pos < size && data[pos] == 0xFF) ++pos;  // fill bytes may precede any marker
    if (pos >= size)
      return fail(ErrorCode::kCorrupt, fmt::format("{}: JPEG ends inside a marker", kWhat));
    const uint8_t marker = data[pos++];
    if (marker == 0xD9) {
      if (!seen_frame || !seen_scan)
        return fail(ErrorCode::kCorrupt, fmt::format("{}: JPEG has no frame or scan", kWhat));
      if (pos != size)
        return fail(ErrorCode::kCorrupt,
                    fmt::format("{}: {} trailing bytes after the JPEG end-of-image marker", kWhat,
                                size - pos));
      return structure;
    }
    if (marker == 0x00 || marker == 0x01 || marker == 0xD8 || (marker >= 0xD0 && marker <= 0xD7))
      return fail(ErrorCode::kCorrupt, fmt::format("{}: stray JPEG marker 0x{:02X} at offset {}",
                                                   kWhat, marker, pos - 1));
    if (size - pos < 2)
      return fail(ErrorCode::kCorrupt, fmt::format("{}: JPEG ends inside a segment", kWhat));
    const size_t segment_bytes = readBe16(data + pos);
    if (segment_bytes < 2 || segment_bytes > size - pos)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: JPEG segment 0x{:02X} at offset {} claims {} bytes, {} left",
                              kWhat, marker, pos - 1, segment_bytes, size - pos));
    const uint8_t* segment = data + pos + 2;
    const size_t body_bytes = segment_bytes - 2;
    pos += segment_bytes;

    const bool is_frame =
        marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
    if (is_frame) {
      if (marker != 0xC0 && marker != 0xC1)
        return fail(ErrorCode::kCorrupt,
                    fmt::format("{}: JPEG frame type 0x{:02X} is not baseline", kWhat, marker));
      if (seen_frame)
        return fail(ErrorCode::kCorrupt, fmt::format("{}: JPEG has two frames", kWhat));
      if (body_bytes < 6 || segment[0] != 8)
        return fail(ErrorCode::kCorrupt,
                    fmt::format("{}: JPEG frame header is not 8-bit baseline", kWhat));
      structure.height_px = readBe16(segment + 1);
      structure.width_px = readBe16(segment + 3);
      structure.components = segment[5];
      if (body_bytes != 6 + 3 * size_t(structure.components))
        return fail(ErrorCode::kCorrupt,
                    fmt::format("{}: JPEG frame header length {} does not match {} components",
                                kWhat, segment_bytes, structure.components));
      seen_frame = true;
    } else if (marker == 0xDA) {
      if (!seen_frame)
        return fail(ErrorCode::kCorrupt, fmt::format("{}: JPEG scan before its frame", kWhat));
      seen_scan = true;
      // Entropy-coded data runs to the next marker that is neither a stuffed 0xFF00 nor a
      // restart marker.
      for (;;) {
        const void* next = std::memchr(data + pos, 0xFF, size - pos);
        if (next == nullptr)
          return fail(ErrorCode::kCorrupt,
                      fmt::format("{}: JPEG scan data runs past the end ({} bytes)", kWhat, size));
        pos = size_t(static_cast<const uint8_t*>(next) - data);
        size_t after = pos + 1;
        while (after < size && data[after] == 0xFF) ++after;
        if (after >= size)
          return fail(ErrorCode::kCorrupt,
                      fmt::format("{}: JPEG scan data runs past the end ({} bytes)", kWhat, size));
        const uint8_t code = data[after];
        if (code == 0x00 || (code >= 0xD0 && code <= 0xD7)) {
          pos = after + 1;
          continue;
        }
        pos = after - 1;  // at the last 0xFF before the marker code
        break;
      }
    }
  }
}

Result<tjhandle> decompressor(JpegDecodeState& state) {
  if (state.decompressor == nullptr) state.decompressor = tjInitDecompress();
  if (state.decompressor == nullptr)
    return fail(ErrorCode::kInternal, fmt::format("{}: cannot create a TurboJPEG decompressor: {}",
                                                  kWhat, tjGetErrorStr2(nullptr)));
  return static_cast<tjhandle>(state.decompressor);
}

}  // namespace

Result<void> decodeJpeg(std::span<const uint8_t> payload, Image& out,
                        const ParentTexels* /*parent*/, CodecScratch* scratch) {
  ScratchRef ref(scratch);
  auto* state = &ref.state<JpegDecodeState>(Codec::kJpeg, CodecSide::kDecode);
  const uint32_t width = out.width_px;
  const uint32_t height = out.height_px;
  const size_t plane_bytes = size_t(width) * height;

  std::span<const uint8_t> jpeg = payload;
  std::span<const uint8_t> alpha_frame;
  if (hasAlpha(out.channels)) {
    if (payload.size() < kAlphaLengthBytes)
      return fail(ErrorCode::kCorrupt, fmt::format("{}: {} bytes, too short for the JPEG length",
                                                   kWhat, payload.size()));
    uint64_t length = 0;
    for (size_t i = 0; i < kAlphaLengthBytes; ++i) length |= uint64_t(payload[i]) << (8 * i);
    if (length > payload.size() - kAlphaLengthBytes)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: JPEG length {} exceeds the {} bytes left", kWhat, length,
                              payload.size() - kAlphaLengthBytes));
    jpeg = payload.subspan(kAlphaLengthBytes, size_t(length));
    alpha_frame = payload.subspan(kAlphaLengthBytes + size_t(length));
  }

  // Everything that can be checked without decoding is checked first, so a payload for
  // another tile size never reaches libjpeg's allocator.
  TESSERA_ASSIGN_OR_RETURN(JpegStructure structure, walkJpeg(jpeg));
  const uint32_t components = colourComponents(out.channels);
  if (structure.width_px != width || structure.height_px != height ||
      structure.components != components) {
    uint32_t stream_channels = structure.components + (hasAlpha(out.channels) ? 1 : 0);
    return geometryMismatch(kWhat, out, structure.width_px, structure.height_px, stream_channels);
  }
  if (jpeg.size() > ULONG_MAX)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: JPEG of {} bytes", kWhat, jpeg.size()));
  TESSERA_ASSIGN_OR_RETURN(tjhandle handle, decompressor(*state));
  int header_width = 0, header_height = 0, subsampling = 0, colorspace = 0;
  if (tjDecompressHeader3(handle, jpeg.data(), jpeg.size(), &header_width, &header_height,
                          &subsampling, &colorspace) != 0) {
    Unexpected error = fail(ErrorCode::kCorrupt,
                            fmt::format("{}: bad JPEG header: {}", kWhat, tjGetErrorStr2(handle)));
    dropHandle(state->decompressor);
    return error;
  }
  const bool colorspace_ok = components == 1 ? colorspace == TJCS_GRAY
                                             : (colorspace == TJCS_YCbCr || colorspace == TJCS_RGB);
  if (uint32_t(header_width) != width || uint32_t(header_height) != height || !colorspace_ok)
    return fail(
        ErrorCode::kCorrupt,
        fmt::format("{}: JPEG header {}x{} colour space {} does not match {}", kWhat, header_width,
                    header_height, colorspace, geometryText(width, height, out.channels)));

  if (hasAlpha(out.channels)) {
    state->plane.resize(plane_bytes);
    TESSERA_TRY(decompressZstdFrame(alpha_frame, state->plane, "jpeg alpha plane", state->alpha));
  }

  uint8_t* colour = out.texels.data();
  size_t colour_stride = size_t(width) * out.channels;
  int pixel_format = out.channels == 1 ? TJPF_GRAY : out.channels == 3 ? TJPF_RGB : TJPF_RGBX;
  if (out.channels == 2) {
    state->gray.resize(plane_bytes);
    colour = state->gray.data();
    colour_stride = width;
    pixel_format = TJPF_GRAY;
  }
  if (tjDecompress2(handle, jpeg.data(), jpeg.size(), colour, int(width), int(colour_stride),
                    int(height), pixel_format, kDecompressFlags) != 0) {
    Unexpected error =
        fail(ErrorCode::kCorrupt,
             fmt::format("{}: JPEG data of {} is corrupt: {}", kWhat,
                         geometryText(width, height, out.channels), tjGetErrorStr2(handle)));
    dropHandle(state->decompressor);
    return error;
  }

  if (out.channels == 2) {
    uint8_t* dst = out.texels.data();
    for (size_t i = 0; i < plane_bytes; ++i) {
      dst[2 * i] = state->gray[i];
      dst[2 * i + 1] = state->plane[i];
    }
  } else if (out.channels == 4) {
    uint8_t* dst = out.texels.data();
    for (size_t i = 0; i < plane_bytes; ++i) dst[4 * i + 3] = state->plane[i];
  }
  return {};
}

}  // namespace tessera::detail
