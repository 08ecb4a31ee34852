#include "png/png.h"

#include <algorithm>
#include <csetjmp>
#include <cstdio>
#include <cstring>

#include <fmt/format.h>
#include <png.h>

#include "codec_internal.h"
#include "png/png_common.h"

namespace tessera::detail {

using namespace png;

namespace {

// Ancillary chunks we never write (text, ICC profiles) are bounded so that a hostile payload
// cannot make libpng buffer megabytes of them.
constexpr png_alloc_size_t kMaxChunkBytes = 1 << 20;
constexpr png_uint_32 kMaxCachedChunks = 16;

void readFromPayload(png_structp png, png_bytep data, size_t bytes) {
  auto* context = static_cast<PngContext*>(png_get_io_ptr(png));
  if (bytes > context->input_bytes - context->input_pos) png_error(png, "truncated PNG stream");
  std::memcpy(data, context->input + context->input_pos, bytes);
  context->input_pos += bytes;
}

// 16-bit images are stored as 16-bit PNG, 8-bit ones as 8-bit; nothing else is accepted.
int expectedBitDepth(const Image& out) {
  return out.sample_type == SampleType::kU16 ? 16 : 8;
}

enum class ReadOutcome { kOk, kLibpngError, kWrongGeometry };

struct PngHeader {
  png_uint_32 width = 0;
  png_uint_32 height = 0;
  int bit_depth = 0;
  int colour_type = 0;
};

// Reads the payload into `out` after checking IHDR against it. On kWrongGeometry, `header`
// holds what the stream declared.
ReadOutcome readPng(PngContext* context, Image* out, PngHeader* header) {
  png_structp png =
      png_create_read_struct(PNG_LIBPNG_VER_STRING, context, onPngError, onPngWarning);
  if (png == nullptr) {
    std::snprintf(context->message, sizeof(context->message), "cannot create a PNG reader");
    return ReadOutcome::kLibpngError;
  }
  png_infop info = png_create_info_struct(png);
  if (info == nullptr || setjmp(context->jump) != 0) {
    png_destroy_read_struct(&png, &info, nullptr);
    if (context->message[0] == '\0')
      std::snprintf(context->message, sizeof(context->message), "cannot create PNG info");
    return ReadOutcome::kLibpngError;
  }
  png_set_read_fn(png, context, readFromPayload);
  // libpng rejects an IHDR larger than the expected tile before allocating rows for it.
  png_set_user_limits(png, out->width_px, out->height_px);
  png_set_chunk_malloc_max(png, kMaxChunkBytes);
  png_set_chunk_cache_max(png, kMaxCachedChunks);
  // Strict: extra compressed data and bad CRCs in ancillary chunks are errors, not warnings;
  // a payload we wrote has neither.
  png_set_benign_errors(png, 0);
  png_set_crc_action(png, PNG_CRC_ERROR_QUIT, PNG_CRC_ERROR_QUIT);
  png_read_info(png, info);
  png_get_IHDR(png, info, &header->width, &header->height, &header->bit_depth, &header->colour_type,
               nullptr, nullptr, nullptr);
  if (header->width != out->width_px || header->height != out->height_px ||
      header->bit_depth != expectedBitDepth(*out) ||
      header->colour_type != colourType(out->channels)) {
    png_destroy_read_struct(&png, &info, nullptr);
    return ReadOutcome::kWrongGeometry;
  }
  // Adam7 payloads are valid PNGs; libpng combines the passes into the rows we give it.
  const int passes = png_set_interlace_handling(png);
  if (header->bit_depth == 16) png_set_swap(png);  // PNG is big-endian, samples are not
  png_read_update_info(png, info);
  if (png_get_rowbytes(png, info) != out->strideBytes()) png_error(png, "unexpected PNG row size");
  for (int pass = 0; pass < passes; ++pass)
    for (uint32_t y = 0; y < out->height_px; ++y) png_read_row(png, out->row(y), nullptr);
  png_read_end(png, nullptr);  // reads and CRC-checks every chunk up to IEND
  png_destroy_read_struct(&png, &info, nullptr);
  return ReadOutcome::kOk;
}

uint32_t readBe32(const uint8_t* p) {
  return uint32_t(p[0]) << 24 | uint32_t(p[1]) << 16 | uint32_t(p[2]) << 8 | p[3];
}

// Signature (8 bytes), then the IHDR chunk: length 13, "IHDR", width, height, bit depth,
// colour type. Reading these by hand gives a precise geometry error before libpng is set up.
constexpr size_t kIhdrPrefixBytes = 8 + 8 + 10;
const uint8_t kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};

const char* colourTypeName(int colour_type) {
  switch (colour_type) {
    case PNG_COLOR_TYPE_GRAY: return "gray";
    case PNG_COLOR_TYPE_GRAY_ALPHA: return "gray+alpha";
    case PNG_COLOR_TYPE_RGB: return "RGB";
    case PNG_COLOR_TYPE_RGB_ALPHA: return "RGBA";
    case PNG_COLOR_TYPE_PALETTE: return "palette";
    default: return "unknown";
  }
}

}  // namespace

Result<void> decodePng(std::span<const uint8_t> payload, Image& out, const ParentTexels* /*parent*/,
                       CodecScratch* /*scratch*/) {
  PngHeader header;
  if (payload.size() < kIhdrPrefixBytes || std::memcmp(payload.data(), kPngSignature, 8) != 0 ||
      std::memcmp(payload.data() + 12, "IHDR", 4) != 0)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: no PNG signature and IHDR ({} bytes)", kWhat, payload.size()));
  header.width = readBe32(payload.data() + 16);
  header.height = readBe32(payload.data() + 20);
  header.bit_depth = payload[24];
  header.colour_type = payload[25];
  if (header.width != out.width_px || header.height != out.height_px ||
      header.bit_depth != expectedBitDepth(out) || header.colour_type != colourType(out.channels))
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: {} expected, stream is {}x{} {}-bit {}", kWhat,
                            geometryText(out.width_px, out.height_px, out.channels), header.width,
                            header.height, header.bit_depth, colourTypeName(header.colour_type)));
  PngContext context;
  context.input = payload.data();
  context.input_bytes = payload.size();
  switch (readPng(&context, &out, &header)) {
    case ReadOutcome::kLibpngError:
      return fail(ErrorCode::kCorrupt, fmt::format("{}: {}", kWhat, context.message));
    case ReadOutcome::kWrongGeometry:
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: {} expected, stream is {}x{} {}-bit {}", kWhat,
                              geometryText(out.width_px, out.height_px, out.channels), header.width,
                              header.height, header.bit_depth, colourTypeName(header.colour_type)));
    case ReadOutcome::kOk: break;
  }
  if (context.input_pos != payload.size())
    return fail(ErrorCode::kCorrupt, fmt::format("{}: {} trailing bytes after IEND", kWhat,
                                                 payload.size() - context.input_pos));
  return {};
}

}  // namespace tessera::detail
