// JPEG band reader over libjpeg-turbo's libjpeg API, scanline by scanline.
//
// Accepted: grayscale (1 channel) and YCbCr or RGB (3 channels, converted to RGB by libjpeg).
// Refused with kUnsupported: CMYK and YCCK (Adobe inverted CMYK needs colour management to
// look right; convert to RGB first). A baseline JPEG costs one MCU row of memory. A
// progressive JPEG must be decoded whole before its first row exists, so libjpeg's
// coefficient buffer (about 2 bytes per sample) is capped at kMaxJpegMemoryBytes; larger
// progressive images are refused with kTooLarge.
//
// libjpeg's corrupt-data warnings ("Premature end of JPEG file", "extraneous bytes before
// marker") are errors here: libjpeg would otherwise fill the missing rows with grey and the
// archive would store a damaged image without anyone noticing.

#include <algorithm>
#include <cerrno>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <string>

#include <fmt/format.h>
// jpeglib.h needs size_t and FILE declared first.
#include <jpeglib.h>

#include <tessera/format.h>

#include "band_reader.h"
#include "file_reader.h"
#include "scanline_reader.h"

namespace tessera::detail {
namespace {

constexpr uint64_t kMaxJpegMemoryBytes = uint64_t(1) << 30;

struct JpegErrorManager {
  jpeg_error_mgr base;  // first member: libjpeg passes a pointer to it
  jmp_buf jump;
  char message[JMSG_LENGTH_MAX] = {};
};

[[noreturn]] void onJpegError(j_common_ptr cinfo) {
  auto* manager = reinterpret_cast<JpegErrorManager*>(cinfo->err);
  manager->base.format_message(cinfo, manager->message);
  std::longjmp(manager->jump, 1);
}

void onJpegMessage(j_common_ptr cinfo, int level) {
  if (level >= 0) return;  // trace messages
  onJpegError(cinfo);      // warnings mean corrupt data: see the file comment
}

class JpegReader final : public ScanlineReader {
 public:
  explicit JpegReader(std::string path) : ScanlineReader(std::move(path)) {
    cinfo_.err = jpeg_std_error(&errors_.base);
    errors_.base.error_exit = onJpegError;
    errors_.base.emit_message = onJpegMessage;
  }
  ~JpegReader() override {
    if (created_) jpeg_destroy_decompress(&cinfo_);
    if (file_) std::fclose(file_);
  }
  JpegReader(const JpegReader&) = delete;
  JpegReader& operator=(const JpegReader&) = delete;

  Result<void> open();

 private:
  // The setjmp-guarded steps hold only trivial locals; each returns false after a libjpeg
  // error, with the message in errors_.message.
  bool readHeader();
  bool startDecompress(J_COLOR_SPACE out_colour_space);
  bool decodeRow(uint8_t* row) override;
  // Reads past the last row to EOI, so a file cut or padded with junk there still fails.
  bool finishDecoding() override;
  const char* decoderMessage() const override { return errors_.message; }

  std::FILE* file_ = nullptr;
  jpeg_decompress_struct cinfo_{};
  JpegErrorManager errors_{};
  bool created_ = false;
};

bool JpegReader::readHeader() {
  if (setjmp(errors_.jump)) return false;
  jpeg_create_decompress(&cinfo_);
  created_ = true;
  // libjpeg-turbo refuses (rather than spills to disk) when a decode needs more than this.
  cinfo_.mem->max_memory_to_use = long(kMaxJpegMemoryBytes);
  jpeg_stdio_src(&cinfo_, file_);
  jpeg_read_header(&cinfo_, TRUE);
  return true;
}

bool JpegReader::startDecompress(J_COLOR_SPACE out_colour_space) {
  if (setjmp(errors_.jump)) return false;
  cinfo_.out_color_space = out_colour_space;
  jpeg_start_decompress(&cinfo_);
  return true;
}

bool JpegReader::finishDecoding() {
  if (setjmp(errors_.jump)) return false;
  jpeg_finish_decompress(&cinfo_);
  return true;
}

bool JpegReader::decodeRow(uint8_t* row) {
  if (setjmp(errors_.jump)) return false;
  JSAMPROW rows[1] = {row};
  if (jpeg_read_scanlines(&cinfo_, rows, 1) != 1) {
    std::snprintf(errors_.message, sizeof(errors_.message), "decoder returned no row");
    return false;
  }
  return true;
}

Result<void> JpegReader::open() {
  file_ = std::fopen(path_.c_str(), "rb");
  if (!file_) {
    return fail(ErrorCode::kIo, fmt::format("{}: cannot open: {}", path_, std::strerror(errno)));
  }
  if (!readHeader()) {
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: truncated or corrupt JPEG header ({})", path_, errors_.message));
  }
  TESSERA_TRY(checkSourceDimensions(path_, cinfo_.image_width, cinfo_.image_height));
  J_COLOR_SPACE out_colour_space = JCS_UNKNOWN;
  uint32_t channels = 0;
  switch (cinfo_.jpeg_color_space) {
    case JCS_GRAYSCALE:
      out_colour_space = JCS_GRAYSCALE;
      channels = 1;
      break;
    case JCS_YCbCr:
    case JCS_RGB:
      out_colour_space = JCS_RGB;
      channels = 3;
      break;
    case JCS_CMYK:
    case JCS_YCCK:
      return fail(ErrorCode::kUnsupported,
                  path_ + ": CMYK JPEG is not supported (gray and RGB only); convert it to RGB");
    default:
      return fail(ErrorCode::kUnsupported,
                  fmt::format("{}: JPEG colour space {} with {} components is not supported", path_,
                              int(cinfo_.jpeg_color_space), cinfo_.num_components));
  }
  const uint64_t samples =
      uint64_t(cinfo_.image_width) * cinfo_.image_height * uint64_t(cinfo_.num_components);
  if (jpeg_has_multiple_scans(&cinfo_) && samples * 2 > kMaxJpegMemoryBytes) {
    return fail(
        ErrorCode::kTooLarge,
        fmt::format("{}: progressive JPEG of {}x{} px needs its whole image in memory "
                    "(over the {} MiB limit); re-save it as baseline",
                    path_, cinfo_.image_width, cinfo_.image_height, kMaxJpegMemoryBytes >> 20));
  }
  if (!startDecompress(out_colour_space)) {
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: cannot start decoding ({})", path_, errors_.message));
  }
  if (cinfo_.output_components != int(channels)) {
    return fail(ErrorCode::kInternal, fmt::format("{}: libjpeg produced {} components, not {}",
                                                  path_, cinfo_.output_components, channels));
  }
  info_.width_px = cinfo_.output_width;
  info_.height_px = cinfo_.output_height;
  info_.channels = channels;
  // An MCU row: what libjpeg decodes at once for a baseline image.
  info_.natural_band_rows =
      std::min<uint32_t>(info_.height_px, uint32_t(std::max(1, cinfo_.max_v_samp_factor)) * 8);
  // A progressive image's coefficients are held whole (2 bytes a sample, capped above); a
  // baseline decoder holds an MCU row per component and its upsampling context.
  info_.buffer_bytes = jpeg_has_multiple_scans(&cinfo_)
                           ? samples * 2
                           : 4 * uint64_t(info_.natural_band_rows) * cinfo_.output_width *
                                 uint64_t(cinfo_.num_components);
  info_.buffer_bytes += uint64_t(1) << 20;
  info_.format = "jpeg";
  info_.metadata["jpeg"] = {{"progressive", jpeg_has_multiple_scans(&cinfo_) != 0}};
  return {};
}

}  // namespace

Result<std::unique_ptr<BandReader>> openJpegReader(const std::string& path) {
  TESSERA_TRY(checkSourceFile(path));
  auto reader = std::make_unique<JpegReader>(path);
  TESSERA_TRY(reader->open());
  return std::unique_ptr<BandReader>(std::move(reader));
}

}  // namespace tessera::detail
