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

// Level 2 with the SUB and UP filters by default: on image-like 256-px tiles this is several
// times faster than libpng's default (level 6, all filters with adaptive choice) and within a
// few percent of its size; tiles that must be small use WebP or a higher effort.
constexpr int kDefaultPngEffort = 2;

void writeToVector(png_structp png, png_bytep data, size_t bytes) {
  auto* context = static_cast<PngContext*>(png_get_io_ptr(png));
  context->output->insert(context->output->end(), data, data + bytes);
}

void flushNothing(png_structp) {}

// Returns false with context->message set when libpng fails.
bool writePng(PngContext* context, const ImageView& tile, int zlib_level, int filters) {
  png_structp png =
      png_create_write_struct(PNG_LIBPNG_VER_STRING, context, onPngError, onPngWarning);
  if (png == nullptr) {
    std::snprintf(context->message, sizeof(context->message), "cannot create a PNG writer");
    return false;
  }
  png_infop info = png_create_info_struct(png);
  if (info == nullptr || setjmp(context->jump) != 0) {
    png_destroy_write_struct(&png, &info);
    if (context->message[0] == '\0')
      std::snprintf(context->message, sizeof(context->message), "cannot create PNG info");
    return false;
  }
  png_set_write_fn(png, context, writeToVector, flushNothing);
  png_set_compression_level(png, zlib_level);
  png_set_filter(png, PNG_FILTER_TYPE_BASE, filters);
  const bool wide = tile.sample_type == SampleType::kU16;
  png_set_IHDR(png, info, tile.width_px, tile.height_px, wide ? 16 : 8, colourType(tile.channels),
               PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_BASE, PNG_FILTER_TYPE_BASE);
  png_write_info(png, info);
  if (wide) png_set_swap(png);  // PNG is big-endian, samples are not
  for (uint32_t y = 0; y < tile.height_px; ++y)
    png_write_row(png, const_cast<png_bytep>(tile.row(y)));
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return true;
}

}  // namespace

Result<std::vector<uint8_t>> encodePng(const ImageView& tile, const EncodeOptions& options,
                                       const ParentTexels* /*parent*/, CodecScratch* /*scratch*/) {
  // effort 1..9 is the zlib level; low levels use the cheap SUB and UP filters, high ones let
  // libpng choose among all five per row.
  const int effort = std::clamp(options.effort != 0 ? options.effort : kDefaultPngEffort, 1, 9);
  const int filters = effort <= 3 ? (PNG_FILTER_SUB | PNG_FILTER_UP) : PNG_ALL_FILTERS;
  std::vector<uint8_t> payload;
  payload.reserve(size_t(tile.width_px) * tile.height_px * tile.texelBytes() / 2 + 1024);
  PngContext context;
  context.output = &payload;
  if (!writePng(&context, tile, effort, filters))
    return fail(
        ErrorCode::kInternal,
        fmt::format("{}: libpng failed to encode {}: {}", kWhat,
                    geometryText(tile.width_px, tile.height_px, tile.channels), context.message));
  payload.shrink_to_fit();
  return payload;
}

}  // namespace tessera::detail
