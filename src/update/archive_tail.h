#pragma once
// An archive opened for appending a version (docs/format.md, "Appended versions"): its
// committed header, root directory and metadata, and the end of its committed bytes, where
// everything new goes until commit() writes the header.

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <tessera/result.h>

#include "format/header.h"
#include "update/archive_update.h"

namespace tessera::detail {

/// Owned by one thread. Holds an exclusive advisory lock (flock) on the file while it lives.
class ArchiveTail {
 public:
  /// Opens `path` read-write and locks it. A header that a torn write left invalid is repaired
  /// from the header copy at the end of the file; an uncommitted tail (an interrupted update) is
  /// cut off. Fails naming the path: not a 1.0 archive, locked by another writer, truncated.
  [[nodiscard]] static Result<ArchiveTail> open(const std::string& path);
  ArchiveTail(ArchiveTail&& other) noexcept;
  ArchiveTail& operator=(ArchiveTail&&) = delete;
  ~ArchiveTail();

  const std::string& path() const { return path_; }
  const FileHeader& header() const { return header_; }
  /// The image records to commit; callers change their levels and may add images.
  std::vector<ImageRecord>& records() { return records_; }
  /// The metadata to commit (the stored JSON object, "{}" when there was none).
  nlohmann::json& metadata() { return metadata_; }
  /// The archive's version as committed: 1 for a file as built.
  uint64_t version() const { return version_; }

  /// Reads a committed block and checks its checksum; kCorrupt naming `what` otherwise.
  [[nodiscard]] Result<std::vector<uint8_t>> readBlock(const BlockRef& block,
                                                       const std::string& what) const;
  /// Writes `bytes` after everything appended so far and returns their reference.
  [[nodiscard]] Result<BlockRef> append(std::span<const uint8_t> bytes);
  /// Counts bytes that the committed version will no longer reference.
  void addDeadBytes(uint64_t bytes) { dead_bytes_ += bytes; }

  /// Appends the root directory, the metadata and the header copy, syncs, then writes the
  /// header at offset 0 and syncs again: the commit. Call once.
  [[nodiscard]] Result<UpdateReport> commit();

 private:
  ArchiveTail(int fd, std::string path) : fd_(fd), path_(std::move(path)) {}
  Result<void> load();
  Result<void> sync();

  int fd_ = -1;
  std::string path_;
  FileHeader header_;
  std::vector<ImageRecord> records_;
  nlohmann::json metadata_;
  uint64_t version_ = 1;
  uint64_t dead_bytes_ = 0;  ///< the committed count, plus what this update adds
  uint64_t end_bytes_ = 0;   ///< where the next append goes
};

}  // namespace tessera::detail
