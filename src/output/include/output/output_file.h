#pragma once
// Files Tessera writes, each invisible until complete: archives, pictures, reports. The one
// place that knows how (O_TMPFILE or a named temporary, fsync, rename over the final path).

#include <cstdint>
#include <span>
#include <string>

#include <tessera/result.h>

namespace tessera::detail {

/// A file being written beside its final path. Created with O_TMPFILE where the file system
/// supports it (nothing is ever visible until commit), else as a named temporary that is
/// removed on destruction. Owned by one thread, except pwrite/pread which are thread-safe.
class TempFile {
 public:
  /// A temporary in the directory of `final_path`, which is checked to be writable.
  [[nodiscard]] static Result<TempFile> create(const std::string& final_path);
  TempFile(TempFile&& other) noexcept;
  TempFile& operator=(TempFile&&) = delete;
  TempFile(const TempFile&) = delete;
  /// Closes and, unless committed, discards the file.
  ~TempFile();

  [[nodiscard]] Result<void> pwrite(uint64_t offset_bytes, std::span<const uint8_t> bytes) const;
  [[nodiscard]] Result<void> pread(uint64_t offset_bytes, std::span<uint8_t> out) const;
  /// fsyncs, then gives the file its final name atomically (replacing any file there) and
  /// fsyncs the directory. After success the object no longer owns a temporary.
  [[nodiscard]] Result<void> commit();
  /// The path errors should name: the final path.
  const std::string& finalPath() const { return final_path_; }

 private:
  TempFile(int fd, std::string final_path, std::string temp_path)
      : fd_(fd), final_path_(std::move(final_path)), temp_path_(std::move(temp_path)) {}
  int fd_ = -1;
  std::string final_path_;
  std::string temp_path_;  ///< empty for O_TMPFILE files
  bool committed_ = false;
};

/// Writes `bytes` as the whole file at `path`: through a TempFile, so readers see the old file
/// or the complete new one, never a partial one. Fails naming the path.
[[nodiscard]] Result<void> writeFileAtomically(const std::string& path,
                                               std::span<const uint8_t> bytes);

}  // namespace tessera::detail
