#include "export/export.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <system_error>

#include <fmt/format.h>

#include "export_writers.h"
#include "output/output_file.h"

namespace tessera::detail {

namespace fs = std::filesystem;

Result<void> writeThroughPartialFile(const std::string& out_path,
                                     const std::function<Result<void>(const std::string&)>& write) {
  TESSERA_TRY(checkOutputPath(out_path));
  const std::string partial = fmt::format("{}.partial-{}", out_path, ::getpid());
  Result<void> written = write(partial);
  if (written) {
    const int fd = ::open(partial.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0 || ::fsync(fd) != 0)
      written = fail(ErrorCode::kIo, fmt::format("{}: cannot sync {}: {}", out_path, partial,
                                                 std::strerror(errno)));
    if (fd >= 0) ::close(fd);
  }
  // Asked again: a FIFO or device node may have appeared at the path meanwhile.
  if (written) written = checkOutputPath(out_path);
  std::error_code error;
  if (written) {
    fs::rename(partial, out_path, error);
    if (!error) return {};
    written = fail(ErrorCode::kIo, fmt::format("{}: cannot rename {} into place: {}", out_path,
                                               partial, error.message()));
  }
  fs::remove(partial, error);
  return written;
}

std::optional<ExportFormat> parseExportFormat(std::string_view text) {
  if (text == "dzi" || text == "deepzoom") return ExportFormat::kDeepZoom;
  if (text == "pmtiles") return ExportFormat::kPmtiles;
  if (text == "mbtiles") return ExportFormat::kMbtiles;
  if (text == "tiff" || text == "tif") return ExportFormat::kTiff;
  return std::nullopt;
}

const char* exportFormatName(ExportFormat format) {
  switch (format) {
    case ExportFormat::kDeepZoom: return "Deep Zoom";
    case ExportFormat::kPmtiles: return "PMTiles";
    case ExportFormat::kMbtiles: return "MBTiles";
    case ExportFormat::kTiff: return "TIFF";
  }
  return "unknown";
}

Result<ExportReport> exportArchive(const Archive& archive, const std::string& out_path,
                                   const ExportOptions& options) {
  if (options.image >= archive.images().size())
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: no image {} (the archive has {})", archive.name(), options.image,
                            archive.images().size()));
  // Deep Zoom, PMTiles and MBTiles tiles are JPEG or PNG pictures for viewers and maps: 8-bit,
  // and wide samples would need a window chosen by the user. The TIFF keeps them as they are.
  if (const SampleType type = archive.images()[options.image].sample_type;
      type != SampleType::kU8 && options.format != ExportFormat::kTiff)
    return fail(ErrorCode::kUnsupported,
                fmt::format("{}: image {} has {} samples, and {} tiles hold 8-bit samples only; "
                            "`--to tiff` exports them as they are",
                            archive.name(), options.image, sampleTypeName(type),
                            exportFormatName(options.format)));
  switch (options.format) {
    case ExportFormat::kDeepZoom: return exportDeepZoom(archive, out_path, options);
    case ExportFormat::kPmtiles: return exportPmtiles(archive, out_path, options);
    case ExportFormat::kMbtiles: return exportMbtiles(archive, out_path, options);
    case ExportFormat::kTiff: return exportTiff(archive, out_path, options);
  }
  return fail(ErrorCode::kInvalidArgument, "unknown export format");
}

}  // namespace tessera::detail
