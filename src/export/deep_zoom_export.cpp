// Deep Zoom exports, as a folder (NAME.dzi beside NAME_files/) or as one zip file laid out as
// `vips dzsave --container zip` writes it (NAME/NAME.dzi and NAME/NAME_files/ inside
// NAME.zip, every entry stored, since the tiles are JPEG or PNG already). Tiles are cut by
// the server's Deep Zoom code, so an export holds exactly what `tessera serve` sends.
#include <fcntl.h>
#include <unistd.h>
#include <zip.h>

#include <cerrno>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <system_error>

#include <fmt/format.h>

#include "export_writers.h"
#include "uniform_pictures.h"
#include "output/output_file.h"
#include "serve/pictures.h"

namespace tessera::detail {

namespace {

namespace fs = std::filesystem;

/// Receives one Deep Zoom tile: its level d (0 = one pixel), column, row and bytes.
using DeepZoomTileSink =
    std::function<Result<void>(uint32_t d, uint32_t col, uint32_t row, const Picture& picture)>;

// Cuts every Deep Zoom tile, level 0 first and row by row, into `sink`.
Result<void> cutDeepZoomTiles(const Archive& archive, const ExportOptions& options,
                              ExportReport& report, const DeepZoomTileSink& sink) {
  const ImageInfo& info = archive.images()[options.image];
  const PictureFormat format = dziFormat(info);
  const uint32_t max_level = dziMaxLevel(info), tile = info.tile_size_px;
  const auto grid = [&](uint32_t d) {
    const uint32_t scale = max_level - d;
    return std::pair{(scaledWidthPx(info, scale) + tile - 1) / tile,
                     (scaledHeightPx(info, scale) + tile - 1) / tile};
  };
  uint64_t total = 0;
  for (uint32_t d = 0; d <= max_level; ++d) total += uint64_t(grid(d).first) * grid(d).second;
  report.tile_format = dziExtension(format);
  UniformPictures uniforms(info, format, options.jpeg_quality);
  for (uint32_t d = 0; d <= max_level; ++d) {
    const auto [cols, rows] = grid(d);
    for (uint32_t row = 0; row < rows; ++row) {
      for (uint32_t col = 0; col < cols; ++col) {
        TESSERA_ASSIGN_OR_RETURN(Picture picture,
                                 exportDziTile(archive, options.image, d, col, row, uniforms));
        TESSERA_TRY(sink(d, col, row, picture));
        report.bytes += picture.bytes.size();
        report.tiles_copied += picture.copied ? 1 : 0;
        ++report.tiles;
        if (options.on_progress) options.on_progress(report.tiles, total);
      }
    }
  }
  report.tiles_uniform = uniforms.tilesServed();
  return {};
}

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

bool endsWith(std::string_view text, std::string_view suffix) {
  return text.size() > suffix.size() &&
         text.compare(text.size() - suffix.size(), suffix.size(), suffix) == 0;
}

Result<std::string> deepZoomFilesFolder(const std::string& out_path) {
  std::string folder = out_path.substr(0, out_path.size() - 4) + "_files";
  std::error_code error;
  if (fs::symlink_status(folder, error).type() != fs::file_type::not_found)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: exists; remove it or choose another name (an export never "
                            "merges into an older one)",
                            folder));
  return folder;
}

Result<ExportReport> exportDeepZoomFolder(const Archive& archive, const std::string& out_path,
                                          const ExportOptions& options) {
  TESSERA_TRY(checkOutputPath(out_path));
  TESSERA_ASSIGN_OR_RETURN(std::string folder, deepZoomFilesFolder(out_path));
  StagingFolder staging(fmt::format("{}.partial-{}", folder, ::getpid()));
  ExportReport report;
  std::error_code error;
  const auto sink = [&](uint32_t d, uint32_t col, uint32_t row,
                        const Picture& picture) -> Result<void> {
    const std::string level_folder = fmt::format("{}/{}", staging.path(), d);
    // Every level has a tile 0_0 and it comes first.
    if (col == 0 && row == 0 && !fs::create_directories(level_folder, error) && error)
      return fail(ErrorCode::kIo,
                  fmt::format("{}: cannot create: {}", level_folder, error.message()));
    return writeWholeFile(fmt::format("{}/{}_{}.{}", level_folder, col, row, report.tile_format),
                          picture.bytes);
  };
  TESSERA_TRY(cutDeepZoomTiles(archive, options, report, sink));
  const std::string descriptor = dziDescriptor(archive.images()[options.image]);
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

// One zip file written entry after entry through minizip (zlib's contrib), which adds the
// Zip64 records by itself once offsets pass 4 GiB or entries pass 65,535.
class ZipWriter {
 public:
  ZipWriter(const ZipWriter&) = delete;
  ZipWriter& operator=(const ZipWriter&) = delete;
  ~ZipWriter() {
    if (zip_) zipClose(zip_, nullptr);
  }

  static Result<std::unique_ptr<ZipWriter>> create(const std::string& path,
                                                   const std::string& shown_path) {
    zipFile zip = zipOpen64(path.c_str(), APPEND_STATUS_CREATE);
    if (!zip)
      return fail(ErrorCode::kIo,
                  fmt::format("{}: cannot create: {}", shown_path, std::strerror(errno)));
    return std::unique_ptr<ZipWriter>(new ZipWriter(zip, shown_path));
  }

  /// Adds `bytes` as the stored (uncompressed) entry `name`.
  Result<void> add(const std::string& name, std::string_view bytes) {
    zip_fileinfo entry{};
    entry.tmz_date = date_;
    const bool ok =
        zipOpenNewFileInZip64(zip_, name.c_str(), &entry, nullptr, 0, nullptr, 0, nullptr,
                              /*method=*/0, /*level=*/0, /*zip64=*/0) == ZIP_OK &&
        zipWriteInFileInZip(zip_, bytes.data(), unsigned(bytes.size())) == ZIP_OK &&
        zipCloseFileInZip(zip_) == ZIP_OK;
    if (!ok)
      return fail(ErrorCode::kIo, fmt::format("{}: writing entry {} failed: {}", shown_path_, name,
                                              std::strerror(errno)));
    return {};
  }

  /// Writes the central directory and closes the file.
  Result<void> close() {
    const int closed = zipClose(zip_, nullptr);
    zip_ = nullptr;
    if (closed != ZIP_OK)
      return fail(ErrorCode::kIo, fmt::format("{}: writing the zip directory failed: {}",
                                              shown_path_, std::strerror(errno)));
    return {};
  }

 private:
  ZipWriter(zipFile zip, std::string shown_path) : zip_(zip), shown_path_(std::move(shown_path)) {
    const std::time_t now = std::time(nullptr);
    std::tm local{};
    localtime_r(&now, &local);
    date_ = {uInt(local.tm_sec),  uInt(local.tm_min), uInt(local.tm_hour),
             uInt(local.tm_mday), uInt(local.tm_mon), uInt(local.tm_year + 1900)};
  }

  zipFile zip_ = nullptr;
  std::string shown_path_;
  tm_zip date_{};
};

Result<ExportReport> exportDeepZoomZip(const Archive& archive, const std::string& out_path,
                                       const ExportOptions& options) {
  const std::string name = fs::path(out_path).stem().string();
  ExportReport report;
  const auto write = [&](const std::string& partial) -> Result<void> {
    TESSERA_ASSIGN_OR_RETURN(std::unique_ptr<ZipWriter> zip, ZipWriter::create(partial, out_path));
    const auto sink = [&](uint32_t d, uint32_t col, uint32_t row,
                          const Picture& picture) -> Result<void> {
      return zip->add(
          fmt::format("{0}/{0}_files/{1}/{2}_{3}.{4}", name, d, col, row, report.tile_format),
          picture.bytes);
    };
    TESSERA_TRY(cutDeepZoomTiles(archive, options, report, sink));
    const std::string descriptor = dziDescriptor(archive.images()[options.image]);
    TESSERA_TRY(zip->add(fmt::format("{0}/{0}.dzi", name), descriptor));
    report.bytes += descriptor.size();
    return zip->close();
  };
  TESSERA_TRY(writeThroughPartialFile(out_path, write));
  std::error_code error;
  report.bytes = fs::file_size(out_path, error);
  return report;
}

}  // namespace

Result<ExportReport> exportDeepZoom(const Archive& archive, const std::string& out_path,
                                    const ExportOptions& options) {
  if (endsWith(out_path, ".zip")) return exportDeepZoomZip(archive, out_path, options);
  if (endsWith(out_path, ".dzi")) return exportDeepZoomFolder(archive, out_path, options);
  return fail(ErrorCode::kInvalidArgument,
              fmt::format("{}: a Deep Zoom export is named NAME.dzi (its tiles go to NAME_files "
                          "beside it) or NAME.zip (both inside one zip, as vips dzsave "
                          "--container zip writes)",
                          out_path));
}

}  // namespace tessera::detail
