#include "band_reader.h"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string_view>
#include <sys/stat.h>

#include <fmt/format.h>

#include <tessera/format.h>

#include "file_reader.h"
#include "grid_reader.h"
#include "mosaic_manifest.h"
#include "mosaic_reader.h"

namespace tessera::detail {
namespace {

constexpr std::string_view kSyntheticPrefix = "synthetic:";

enum class SourceKind { kTiff, kPng, kJpeg, kManifest, kUnknown };

// Content decides, never the extension: a ".tif" that is really a PNG is common in the wild
// (exports renamed by hand), and the magic bytes are unambiguous.
SourceKind sniff(const uint8_t* bytes, size_t size) {
  auto starts = [&](std::string_view magic) {
    return size >= magic.size() && std::memcmp(bytes, magic.data(), magic.size()) == 0;
  };
  using namespace std::string_view_literals;
  if (starts("II*\0"sv) || starts("MM\0*"sv) || starts("II+\0"sv) || starts("MM\0+"sv)) {
    return SourceKind::kTiff;
  }
  if (starts("\x89PNG\r\n\x1a\n"sv)) return SourceKind::kPng;
  if (starts("\xff\xd8\xff"sv)) return SourceKind::kJpeg;
  if (looksLikeManifest(bytes, size)) return SourceKind::kManifest;
  return SourceKind::kUnknown;
}

std::string hexPrefix(const uint8_t* bytes, size_t size) {
  std::string out;
  for (size_t i = 0; i < size; ++i) out += fmt::format("{}{:02x}", i ? " " : "", bytes[i]);
  return out;
}

}  // namespace

Result<uint64_t> checkSourceFile(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    const int err = errno;
    if (err == ENOENT || err == ENOTDIR) return fail(ErrorCode::kNotFound, path + ": no such file");
    return fail(ErrorCode::kIo, fmt::format("{}: cannot stat: {}", path, std::strerror(err)));
  }
  if (S_ISDIR(st.st_mode)) return fail(ErrorCode::kIo, path + ": is a directory, not an image");
  if (!S_ISREG(st.st_mode)) return fail(ErrorCode::kIo, path + ": not a regular file");
  if (st.st_size == 0) return fail(ErrorCode::kCorrupt, path + ": empty file");
  return uint64_t(st.st_size);
}

Result<void> checkSourceDimensions(const std::string& path, uint64_t width_px, uint64_t height_px) {
  if (width_px == 0 || height_px == 0) {
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: zero image dimensions ({}x{})", path, width_px, height_px));
  }
  if (width_px > kMaxImageSidePx || height_px > kMaxImageSidePx) {
    return fail(ErrorCode::kTooLarge,
                fmt::format("{}: image of {}x{} px exceeds the limit of {} px per side", path,
                            width_px, height_px, kMaxImageSidePx));
  }
  return {};
}

namespace {

/// An image file by its content; a mosaic manifest too when `allow_manifest` (not for the
/// images a manifest names: manifests do not nest).
Result<std::unique_ptr<BandReader>> openFile(const std::string& path, bool allow_manifest) {
  TESSERA_TRY(checkSourceFile(path));
  std::FILE* file = std::fopen(path.c_str(), "rb");
  if (!file) {
    return fail(ErrorCode::kIo, fmt::format("{}: cannot open: {}", path, std::strerror(errno)));
  }
  // Enough for a manifest's leading whitespace as pretty-printers write it.
  uint8_t magic[64] = {};
  const size_t got = std::fread(magic, 1, sizeof(magic), file);
  std::fclose(file);
  switch (sniff(magic, got)) {
    case SourceKind::kTiff: return openTiffReader(path);
    case SourceKind::kPng: return openPngReader(path);
    case SourceKind::kJpeg: return openJpegReader(path);
    case SourceKind::kManifest:
      if (allow_manifest) return openMosaicReader(path);
      return fail(ErrorCode::kUnsupported,
                  path + ": a mosaic manifest, not an image (a manifest cannot name another)");
    case SourceKind::kUnknown: break;
  }
  return fail(ErrorCode::kUnsupported,
              fmt::format("{}: not a TIFF, PNG or JPEG image{} (starts with {})", path,
                          allow_manifest ? " or a mosaic manifest" : "",
                          hexPrefix(magic, std::min<size_t>(got, 8))));
}

}  // namespace

Result<std::unique_ptr<BandReader>> openBandReader(const std::string& source) {
  if (source.starts_with(kSyntheticPrefix)) {
    return openSyntheticReader(source.substr(kSyntheticPrefix.size()));
  }
  if (source.starts_with(kGridPrefix)) return openGridReader(source);
  return openFile(source, true);
}

Result<std::unique_ptr<BandReader>> openImageFileReader(const std::string& path) {
  return openFile(path, false);
}

}  // namespace tessera::detail
