#pragma once
// The archives a server serves, opened once at start and immutable afterwards.

#include <cstdint>
#include <ctime>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <tessera/archive.h>
#include <tessera/result.h>

namespace tessera::detail {

/// One served archive. Immutable after loadCatalog; shared by every server thread.
struct ServedArchive {
  std::string name;  ///< file stem, [A-Za-z0-9._-]+
  std::string path;
  std::shared_ptr<Archive> archive;
  std::shared_ptr<const ByteSource> source;  ///< the archive's file
  uint64_t file_bytes = 0;
  /// Strong validator from the file's identity: "\"<size>-<mtime ns>-<inode>\"" in hex. The
  /// server treats archives as immutable; replacing a file needs a restart.
  std::string etag;
  std::time_t modified = 0;  ///< for Last-Modified and If-Range dates
  /// A descriptor of the served file kept only to fstat it: a file rewritten in place (same
  /// inode) would otherwise be served as new bytes under the old ETag, which no client can
  /// detect. A file replaced by rename keeps being served from the old inode, consistently.
  int stat_fd = -1;
  uint64_t mtime_ns = 0;
  /// In an object store (s3://): there is no file to stat, and the source itself refuses
  /// bytes of another version of the object (the HTTP source's ETag rule), failing the read.
  bool remote = false;
  ServedArchive() = default;
  ServedArchive(const ServedArchive&) = delete;
  ServedArchive& operator=(const ServedArchive&) = delete;
  ~ServedArchive();
  /// False once the file's size or modification time differ from those at start. Always true
  /// for a remote archive, whose source checks its version on every read.
  bool unchangedOnDisk() const;
};

/// Archives by name.
using Catalog = std::map<std::string, std::shared_ptr<const ServedArchive>>;

/// True for names made only of [A-Za-z0-9._-], not empty, and not "." or "..".
bool isValidArchiveName(std::string_view name);

/// Opens every archive in `paths` (files, or folders whose `.tess` files are all served).
/// Fails naming the path: missing, not an archive, a name outside [A-Za-z0-9._-]+, the same
/// name twice, or nothing to serve.
[[nodiscard]] Result<Catalog> loadCatalog(const std::vector<std::string>& paths);

}  // namespace tessera::detail
