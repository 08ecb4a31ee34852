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
