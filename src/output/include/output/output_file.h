#pragma once
// Files Tessera writes, each invisible until complete: archives, pictures, reports. The one
// place that knows how (O_TMPFILE or a named temporary, fsync, rename over the final path).

#include <cstdint>
#include <span>
#include <string>

#include <tessera/result.h>

namespace tessera::detail {

/// Checks that `path` may be replaced by a file Tessera writes: it does not exist, or it is
/// a regular file (a symbolic link is judged by what it points to). A device node, a FIFO, a
/// socket or a directory is refused with kInvalidArgument naming the path and what it is: the
/// rename that completes a write would replace `/dev/null` or a pipe with a regular file.
[[nodiscard]] Result<void> checkOutputPath(const std::string& path);

/// Bytes free to an unprivileged writer on the file system holding `directory`, and which file
/// system that is.
struct DiskSpace {
  uint64_t available_bytes = 0;  ///< statvfs f_bavail x f_frsize
  uint64_t device = 0;           ///< st_dev of the directory: equal values share the space
};

/// The space at `directory`; fails naming it when it cannot be examined.
[[nodiscard]] Result<DiskSpace> diskSpaceAt(const std::string& directory);

/// The directory a file at `path` goes into ("." for a bare name).
std::string directoryOf(const std::string& path);

/// A file being written beside its final path. Created with O_TMPFILE where the file system
/// supports it (nothing is ever visible until commit), else as a named temporary that is
/// removed on destruction. Owned by one thread, except pwrite/pread which are thread-safe.
class TempFile {
 public:
  /// A temporary in the directory of `final_path`, which is checked to be writable; fails
  /// when `final_path` exists and is not a regular file (checkOutputPath).
  [[nodiscard]] static Result<TempFile> create(const std::string& final_path);
  /// A scratch file in `directory` that is never committed (a build's spool): anonymous where
  /// the file system allows, else a named temporary removed on destruction. Errors name
  /// `purpose` (e.g. "scan.tess: spool") and the directory.
  [[nodiscard]] static Result<TempFile> createScratch(const std::string& directory,
                                                      const std::string& purpose);
  TempFile(TempFile&& other) noexcept;
  TempFile& operator=(TempFile&&) = delete;
  TempFile(const TempFile&) = delete;
  /// Closes and, unless committed, discards the file.
  ~TempFile();

  [[nodiscard]] Result<void> pwrite(uint64_t offset_bytes, std::span<const uint8_t> bytes) const;
  [[nodiscard]] Result<void> pread(uint64_t offset_bytes, std::span<uint8_t> out) const;
  /// Asks the kernel to start writing `[offset_bytes, +bytes)` to the disk now, without
  /// waiting (sync_file_range), so that commit's fsync finds less left to write. A hint:
  /// where the kernel refuses, the fsync writes it all as before.
  void startWriteback(uint64_t offset_bytes, uint64_t bytes) const;
  /// fsyncs, then gives the file its final name atomically (replacing any regular file there;
  /// checkOutputPath is asked again first, for a node created while the file was written) and
  /// fsyncs the directory. After success the object no longer owns a temporary. Not for a
  /// scratch file.
  [[nodiscard]] Result<void> commit();
  /// The path errors should name: the final path.
  const std::string& finalPath() const { return final_path_; }

 private:
  TempFile(int fd, std::string final_path, std::string temp_path)
      : fd_(fd), final_path_(std::move(final_path)), temp_path_(std::move(temp_path)) {}
  /// Opens an unnamed file in `dir`, else a named one at `fallback_path`; `what` names it in
  /// errors.
  static Result<TempFile> openIn(const std::string& dir, const std::string& what,
                                 const std::string& fallback_path);
  int fd_ = -1;
  std::string final_path_;
  std::string temp_path_;  ///< empty for O_TMPFILE files
  bool committed_ = false;
  bool scratch_ = false;  ///< made by createScratch: never committed
};

/// Writes `bytes` as the whole file at `path`: through a TempFile, so readers see the old file
/// or the complete new one, never a partial one. Fails naming the path.
[[nodiscard]] Result<void> writeFileAtomically(const std::string& path,
                                               std::span<const uint8_t> bytes);

}  // namespace tessera::detail
