// PNG band reader over libpng, one row per png_read_row, so memory is one row plus zlib's
// window whatever the height.
//
// Accepted: 8- and 16-bit gray, gray+alpha, RGB, RGBA (16-bit samples stay 16-bit: a u16
// image); palette images expanded to RGB (RGBA when a tRNS chunk gives transparency);
// 1/2/4-bit gray expanded to 8 bits; tRNS on gray or RGB turns into an alpha channel. Refused
// with kUnsupported:
//  - interlaced (Adam7) images: their first pass already spans the whole height, so rows come
//    out only after the whole image is decoded into memory, which is what a band reader exists
//    to avoid. Re-save without interlacing (e.g. `convert -interlace none`).
//
// libpng reports errors by longjmp. Every function that calls setjmp here holds only trivial
// locals, so nothing is skipped by the jump; the message is copied into the reader first.

#include <algorithm>
#include <cerrno>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <string>

#include <fmt/format.h>
#include <png.h>

#include <tessera/format.h>

#include "band_reader.h"
#include "file_reader.h"
#include "scanline_reader.h"

namespace tessera::detail {
namespace {

// libpng's own default caps a side at 1000000 px; ours is kMaxImageSidePx, checked with a
// clearer message after the header is read. Ancillary chunks (text, ICC) are capped to keep a
// hostile chunk length from allocating: 8 MiB holds any real ICC profile or text block.
constexpr png_alloc_size_t kMaxChunkBytes = png_alloc_size_t(8) << 20;

struct PngMessages {
  char error[256] = {};
};

void onPngError(png_structp png, png_const_charp message) {
  auto* messages = static_cast<PngMessages*>(png_get_error_ptr(png));
  std::snprintf(messages->error, sizeof(messages->error), "%s", message);
  png_longjmp(png, 1);
}

// Warnings (bad ancillary chunks, an sRGB profile mismatch) leave the pixels intact.
void onPngWarning(png_structp, png_const_charp) {}

class PngReader final : public ScanlineReader {
 public:
  explicit PngReader(std::string path) : ScanlineReader(std::move(path)) {}
  ~PngReader() override {
    if (png_) png_destroy_read_struct(&png_, &png_info_, nullptr);
    if (file_) std::fclose(file_);
  }
  PngReader(const PngReader&) = delete;
  PngReader& operator=(const PngReader&) = delete;

  Result<void> open();

 private:
  struct Header {
    png_uint_32 width = 0;
    png_uint_32 height = 0;
    int bit_depth = 0;
    int colour_type = 0;
    int interlace = 0;
    int channels = 0;  // after the expansions, filled by setUpTransforms
    size_t row_bytes = 0;
  };
  // The setjmp-guarded steps: each returns false after a libpng error (message in
  // messages_.error).
  bool readHeader(Header* header);
  bool setUpTransforms(Header* header);
  // Sets up the transforms before the first row and checks the layout they give.
  bool startRows();
  bool decodeRow(uint8_t* row) override;
  // Reads past the last row to IEND, so a file cut after its pixels still fails.
  bool finishDecoding() override;
  const char* decoderMessage() const override { return messages_.error; }

  std::FILE* file_ = nullptr;
  // The header as read; the transforms are set up (png_read_update_info) only when the first
  // row is asked for: libpng then allocates and clears two rows of the claimed width, which
  // the build's memory check must see before they exist.
  Header header_;
  bool rows_started_ = false;
  png_structp png_ = nullptr;
  png_infop png_info_ = nullptr;
  PngMessages messages_;
};

bool PngReader::readHeader(Header* header) {
  if (setjmp(png_jmpbuf(png_))) return false;
  png_init_io(png_, file_);
  png_set_user_limits(png_, 0x7fffffff, 0x7fffffff);
  png_set_chunk_malloc_max(png_, kMaxChunkBytes);
  png_read_info(png_, png_info_);
  png_get_IHDR(png_, png_info_, &header->width, &header->height, &header->bit_depth,
               &header->colour_type, &header->interlace, nullptr, nullptr);
  return true;
}

bool PngReader::setUpTransforms(Header* header) {
  if (setjmp(png_jmpbuf(png_))) return false;
  if (header->colour_type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png_);
  if (header->colour_type == PNG_COLOR_TYPE_GRAY && header->bit_depth < 8) {
    png_set_expand_gray_1_2_4_to_8(png_);
  }
  if (png_get_valid(png_, png_info_, PNG_INFO_tRNS)) png_set_tRNS_to_alpha(png_);
  if (header->bit_depth == 16) png_set_swap(png_);  // PNG is big-endian, samples host order
  png_read_update_info(png_, png_info_);
  header->channels = png_get_channels(png_, png_info_);
  header->row_bytes = png_get_rowbytes(png_, png_info_);
  return true;
}

bool PngReader::startRows() {
  if (!setUpTransforms(&header_)) return false;
  if (header_.channels != int(info_.channels) ||
      header_.row_bytes !=
          size_t(header_.width) * info_.channels * sampleBytes(info_.sample_type)) {
    std::snprintf(messages_.error, sizeof(messages_.error),
                  "unexpected PNG layout: %d channels, %zu bytes per row", header_.channels,
                  header_.row_bytes);
    return false;
  }
  rows_started_ = true;
  return true;
}

bool PngReader::decodeRow(uint8_t* row) {
  if (!rows_started_ && !startRows()) return false;
  if (setjmp(png_jmpbuf(png_))) return false;
  png_read_row(png_, row, nullptr);
  return true;
}

bool PngReader::finishDecoding() {
  if (setjmp(png_jmpbuf(png_))) return false;
  png_read_end(png_, nullptr);
  return true;
}

Result<void> PngReader::open() {
  file_ = std::fopen(path_.c_str(), "rb");
  if (!file_) {
    return fail(ErrorCode::kIo, fmt::format("{}: cannot open: {}", path_, std::strerror(errno)));
  }
  png_byte signature[8] = {};
  const size_t got = std::fread(signature, 1, sizeof(signature), file_);
  if (got < sizeof(signature) || png_sig_cmp(signature, 0, sizeof(signature)) != 0) {
    return fail(ErrorCode::kCorrupt, path_ + ": not a PNG file (bad signature)");
  }
  png_ = png_create_read_struct(PNG_LIBPNG_VER_STRING, &messages_, onPngError, onPngWarning);
  if (png_) png_info_ = png_create_info_struct(png_);
  if (!png_ || !png_info_) return fail(ErrorCode::kInternal, path_ + ": cannot set up libpng");
  png_set_sig_bytes(png_, sizeof(signature));

  Header& header = header_;
  if (!readHeader(&header)) {
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: truncated or corrupt PNG header ({})", path_, messages_.error));
  }
  TESSERA_TRY(checkSourceDimensions(path_, header.width, header.height));
  if (header.interlace != PNG_INTERLACE_NONE) {
    return fail(ErrorCode::kUnsupported,
                path_ +
                    ": interlaced (Adam7) PNG is not supported: it cannot be read in bands; "
                    "re-save it without interlacing");
  }
  // The channels the transforms below will give (palette and low-bit gray expanded, tRNS as
  // alpha), known from the header without setting them up yet.
  const bool transparency = png_get_valid(png_, png_info_, PNG_INFO_tRNS) != 0;
  uint32_t channels = 0;
  switch (header.colour_type) {
    case PNG_COLOR_TYPE_GRAY: channels = transparency ? 2 : 1; break;
    case PNG_COLOR_TYPE_GRAY_ALPHA: channels = 2; break;
    case PNG_COLOR_TYPE_RGB:
    case PNG_COLOR_TYPE_PALETTE: channels = transparency ? 4 : 3; break;
    case PNG_COLOR_TYPE_RGB_ALPHA: channels = 4; break;
    default:
      return fail(ErrorCode::kUnsupported, fmt::format("{}: PNG colour type {} is not supported",
                                                       path_, header.colour_type));
  }
  info_.width_px = header.width;
  info_.height_px = header.height;
  info_.channels = channels;
  info_.sample_type = header.bit_depth == 16 ? SampleType::kU16 : SampleType::kU8;
  info_.natural_band_rows = std::min<uint32_t>(header.height, 64);
  // libpng's current and previous rows (before and after the expansions) and zlib's window.
  info_.buffer_bytes =
      4 * (uint64_t(header.width) * channels * (header.bit_depth == 16 ? 2 : 1) + 1) +
      (uint64_t(1) << 20);
  info_.format = "png";
  static constexpr const char* kColourNames[] = {"gray",       "?", "rgb", "palette",
                                                 "gray+alpha", "?", "rgba"};
  info_.metadata["png"] = {
      {"colour_type", header.colour_type <= 6 ? kColourNames[header.colour_type] : "?"},
      {"bit_depth", header.bit_depth},
  };
  return {};
}

}  // namespace

Result<std::unique_ptr<BandReader>> openPngReader(const std::string& path) {
  TESSERA_TRY(checkSourceFile(path));
  auto reader = std::make_unique<PngReader>(path);
  TESSERA_TRY(reader->open());
  return std::unique_ptr<BandReader>(std::move(reader));
}

}  // namespace tessera::detail
