#include "catalog.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <ctime>
#include <filesystem>

#include <fmt/format.h>

#include <tessera/http_source.h>

namespace tessera::detail {

bool isValidArchiveName(std::string_view name) {
  if (name.empty() || name == "." || name == "..") return false;
  return std::all_of(name.begin(), name.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' ||
           c == '_' || c == '-';
  });
}

namespace {

/// An archive in an object store: named by its key's stem, validated by the header's own
/// checksum (which covers the file's size and the checksums of its root and metadata, so any
/// other version of the archive has another), and dated by when it was opened.
Result<std::shared_ptr<ServedArchive>> openRemoteArchive(const std::string& url) {
  TESSERA_ASSIGN_OR_RETURN(std::shared_ptr<ByteSource> source, openS3Source(url));
  TESSERA_ASSIGN_OR_RETURN(std::shared_ptr<Archive> archive, Archive::open(source));
  std::array<uint8_t, 8> header_checksum{};
  TESSERA_TRY(source->read(120, header_checksum));
  uint64_t checksum = 0;
  for (size_t i = 0; i < header_checksum.size(); ++i)
    checksum |= uint64_t(header_checksum[i]) << (8 * i);
  auto served = std::make_shared<ServedArchive>();
  served->archive = archive;
  served->source = source;
  served->file_bytes = source->sizeBytes();
  served->etag = fmt::format("\"{:x}-{:x}\"", served->file_bytes, checksum);
  served->modified = std::time(nullptr);
  served->remote = true;
  return served;
}

Result<void> addArchive(const std::string& path, Catalog& catalog) {
  std::string name = std::filesystem::path(path).stem().string();
  if (!isValidArchiveName(name))
    return Unexpected(
        ErrorCode::kInvalidArgument,
        fmt::format("{}: archive name \"{}\" has characters outside [A-Za-z0-9._-]", path, name));
  if (catalog.count(name))
    return Unexpected(ErrorCode::kInvalidArgument,
                      fmt::format("{}: archive name \"{}\" is already served from {}", path, name,
                                  catalog.at(name)->path));
  if (path.rfind("s3://", 0) == 0) {
    TESSERA_ASSIGN_OR_RETURN(std::shared_ptr<ServedArchive> served, openRemoteArchive(path));
    served->name = name;
    served->path = path;
    catalog[name] = std::move(served);
    return {};
  }
  struct stat status {};
  if (::stat(path.c_str(), &status) != 0)
    return Unexpected(ErrorCode::kNotFound, fmt::format("{}: cannot stat the file", path));
  TESSERA_ASSIGN_OR_RETURN(std::shared_ptr<ByteSource> source, openFileSource(path));
  TESSERA_ASSIGN_OR_RETURN(std::shared_ptr<Archive> archive, Archive::open(source));
  auto served = std::make_shared<ServedArchive>();
  served->name = name;
  served->path = path;
  served->archive = archive;
  served->source = source;
  served->file_bytes = source->sizeBytes();
  const uint64_t mtime_ns =
      uint64_t(status.st_mtim.tv_sec) * 1000000000ull + uint64_t(status.st_mtim.tv_nsec);
  served->etag =
      fmt::format("\"{:x}-{:x}-{:x}\"", served->file_bytes, mtime_ns, uint64_t(status.st_ino));
  served->modified = status.st_mtim.tv_sec;
  served->mtime_ns = mtime_ns;
  served->stat_fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (served->stat_fd < 0)
    return Unexpected(ErrorCode::kIo, fmt::format("{}: cannot open the file", path));
  catalog[name] = std::move(served);
  return {};
}

}  // namespace

ServedArchive::~ServedArchive() {
  if (stat_fd >= 0) ::close(stat_fd);
}

bool ServedArchive::unchangedOnDisk() const {
  if (remote) return true;
  struct stat status {};
  if (stat_fd < 0 || ::fstat(stat_fd, &status) != 0) return false;
  const uint64_t now_ns =
      uint64_t(status.st_mtim.tv_sec) * 1000000000ull + uint64_t(status.st_mtim.tv_nsec);
  return uint64_t(status.st_size) == file_bytes && now_ns == mtime_ns;
}

Result<Catalog> loadCatalog(const std::vector<std::string>& paths) {
  Catalog catalog;
  for (const std::string& path : paths) {
    std::error_code ec;
    if (path.rfind("s3://", 0) != 0 && std::filesystem::is_directory(path, ec)) {
      std::vector<std::string> files;
      for (const auto& entry : std::filesystem::directory_iterator(path, ec))
        if (entry.path().extension() == ".tess" && entry.is_regular_file())
          files.push_back(entry.path().string());
      if (ec)
        return Unexpected(ErrorCode::kIo,
                          fmt::format("{}: cannot list the folder: {}", path, ec.message()));
      if (files.empty())
        return Unexpected(ErrorCode::kNotFound,
                          fmt::format("{}: the folder holds no .tess archive", path));
      std::sort(files.begin(), files.end());
      for (const std::string& file : files) TESSERA_TRY(addArchive(file, catalog));
    } else {
      TESSERA_TRY(addArchive(path, catalog));
    }
  }
  if (catalog.empty()) return Unexpected(ErrorCode::kInvalidArgument, "serve: no archive to serve");
  return catalog;
}

}  // namespace tessera::detail
