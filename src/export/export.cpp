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
#include "serve/pictures.h"

namespace tessera::detail {

namespace {

namespace fs = std::filesystem;

Result<void> writeWholeFile(const std::string& path, std::string_view bytes) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0)
    return fail(ErrorCode::kIo, fmt::format("{}: cannot create: {}", path, std::strerror(errno)));
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int error = errno;
      ::close(fd);
      return fail(ErrorCode::kIo, fmt::format("{}: write failed: {}", path, std::strerror(error)));
    }
    done += size_t(n);
  }
  if (::close(fd) != 0)
    return fail(ErrorCode::kIo, fmt::format("{}: close failed: {}", path, std::strerror(errno)));
  return {};
}

// Removes a staging folder when the export fails before it is renamed into place.
class StagingFolder {
 public:
  explicit StagingFolder(std::string path) : path_(std::move(path)) {}
  StagingFolder(const StagingFolder&) = delete;
  StagingFolder& operator=(const StagingFolder&) = delete;
  ~StagingFolder() {
    std::error_code ignored;
    if (!path_.empty()) fs::remove_all(path_, ignored);
  }
  const std::string& path() const { return path_; }
  void release() { path_.clear(); }

 private:
  std::string path_;
};

Result<std::string> deepZoomFilesFolder(const std::string& out_path) {
  constexpr std::string_view kSuffix = ".dzi";
  if (out_path.size() <= kSuffix.size() ||
      out_path.compare(out_path.size() - kSuffix.size(), kSuffix.size(), kSuffix) != 0)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: a Deep Zoom export is named NAME.dzi (its tiles go to "
                            "NAME_files beside it)",
                            out_path));
  std::string folder = out_path.substr(0, out_path.size() - kSuffix.size()) + "_files";
  std::error_code error;
  if (fs::symlink_status(folder, error).type() != fs::file_type::not_found)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: exists; remove it or choose another name (an export never "
                            "merges into an older one)",
                            folder));
  return folder;
}

Result<ExportReport> exportDeepZoom(const Archive& archive, const std::string& out_path,
                                    const ExportOptions& options) {
  TESSERA_TRY(checkOutputPath(out_path));
  TESSERA_ASSIGN_OR_RETURN(std::string folder, deepZoomFilesFolder(out_path));
  const ImageInfo& info = archive.images()[options.image];
  const PictureFormat format = dziFormat(info);
  const uint32_t max_level = dziMaxLevel(info), tile = info.tile_size_px;
  uint64_t total = 0;
  for (uint32_t d = 0; d <= max_level; ++d) {
    const uint32_t scale = max_level - d;
    total += uint64_t((scaledWidthPx(info, scale) + tile - 1) / tile) *
             ((scaledHeightPx(info, scale) + tile - 1) / tile);
  }
  StagingFolder staging(fmt::format("{}.partial-{}", folder, ::getpid()));
  std::error_code error;
  ExportReport report;
  report.tile_format = dziExtension(format);
  for (uint32_t d = 0; d <= max_level; ++d) {
    const std::string level_folder = fmt::format("{}/{}", staging.path(), d);
    if (!fs::create_directories(level_folder, error) && error)
      return fail(ErrorCode::kIo,
                  fmt::format("{}: cannot create: {}", level_folder, error.message()));
    const uint32_t scale = max_level - d;
    const uint32_t cols = (scaledWidthPx(info, scale) + tile - 1) / tile;
    const uint32_t rows = (scaledHeightPx(info, scale) + tile - 1) / tile;
    for (uint32_t row = 0; row < rows; ++row) {
      for (uint32_t col = 0; col < cols; ++col) {
        TESSERA_ASSIGN_OR_RETURN(Picture picture, renderDziTile(archive, options.image, d, col, row,
                                                                format, options.jpeg_quality));
        TESSERA_TRY(writeWholeFile(
            fmt::format("{}/{}_{}.{}", level_folder, col, row, report.tile_format), picture.bytes));
        report.bytes += picture.bytes.size();
        report.tiles_copied += picture.copied ? 1 : 0;
        ++report.tiles;
        if (options.on_progress) options.on_progress(report.tiles, total);
      }
    }
  }
  const std::string descriptor = dziDescriptor(info);
  TESSERA_ASSIGN_OR_RETURN(TempFile dzi, TempFile::create(out_path));
  TESSERA_TRY(
      dzi.pwrite(0, {reinterpret_cast<const uint8_t*>(descriptor.data()), descriptor.size()}));
  fs::rename(staging.path(), folder, error);
  if (error)
    return fail(ErrorCode::kIo, fmt::format("{}: cannot rename {} into place: {}", folder,
                                            staging.path(), error.message()));
  staging.release();
  if (Result<void> committed = dzi.commit(); !committed) {
    fs::remove_all(folder, error);
    return forwardError(committed);
  }
  report.bytes += descriptor.size();
  return report;
}

}  // namespace

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

Result<ExportReport> exportArchive(const Archive& archive, const std::string& out_path,
                                   const ExportOptions& options) {
  if (options.image >= archive.images().size())
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: no image {} (the archive has {})", archive.name(), options.image,
                            archive.images().size()));
  switch (options.format) {
    case ExportFormat::kDeepZoom: return exportDeepZoom(archive, out_path, options);
    case ExportFormat::kPmtiles: return exportPmtiles(archive, out_path, options);
    case ExportFormat::kMbtiles: return exportMbtiles(archive, out_path, options);
    case ExportFormat::kTiff: return exportTiff(archive, out_path, options);
  }
  return fail(ErrorCode::kInvalidArgument, "unknown export format");
}

}  // namespace tessera::detail
