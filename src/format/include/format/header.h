#pragma once
// The fixed header and the root directory (docs/format.md, sections "Header" and
// "Root directory"). Pure: bytes in, structs out.

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <tessera/format.h>
#include <tessera/result.h>

namespace tessera::detail {

inline constexpr uint8_t kMagic[8] = {0x89, 'T', 'E', 'S', 'S', '\r', '\n', 0x1A};
inline constexpr uint32_t kHeaderBytes = 128;
/// Bytes a reader fetches first; the writer fits header, root directory and, when they fit,
/// the page indexes and metadata in it, so one read (one HTTP request) opens an archive.
inline constexpr uint32_t kHeaderRegionBytes = 16384;
inline constexpr uint32_t kMaxHeaderRegionBytes = 1u << 20;
inline constexpr uint32_t kImageRecordBytes = 32;
inline constexpr uint32_t kLevelRecordBytes = 32;
/// Levels of a 2^24 px image with 64 px tiles: 19; 32 leaves room without trusting input.
inline constexpr uint32_t kMaxLevels = 32;
/// Metadata is for humans and tools, not a data channel: bounded so a hostile header cannot
/// make a reader allocate much.
inline constexpr uint32_t kMaxMetadataBytes = 16u << 20;

/// Where a block of bytes lives and its checksum.
struct BlockRef {
  uint64_t offset_bytes = 0;
  uint64_t length_bytes = 0;
  uint64_t checksum = 0;
  friend bool operator==(const BlockRef&, const BlockRef&) = default;
};

/// A BlockRef's 24 bytes: offset, length, checksum, each u64 little-endian.
inline constexpr size_t kBlockRefBytes = 24;
void storeBlockRef(uint8_t* p, const BlockRef& block);
BlockRef loadBlockRef(const uint8_t* p);
/// A block is either absent (all zero) or lies after the fixed header and inside a file of
/// `file_bytes`; kCorrupt naming `what` otherwise.
Result<void> checkBlockInFile(const BlockRef& block, uint64_t file_bytes, const std::string& what);

/// The 128-byte header at offset 0.
struct FileHeader {
  uint16_t version_major = kFormatVersionMajor;
  uint16_t version_minor = kFormatVersionMinor;
  uint32_t header_region_bytes = kHeaderRegionBytes;  ///< multiple of 4096, 4096..1 MiB
  uint64_t file_bytes = 0;                            ///< whole file; must equal the source size
  uint32_t image_count = 0;                           ///< 1..kMaxImages
  BlockRef root;                                      ///< the root directory
  BlockRef metadata;                                  ///< UTF-8 JSON object
  friend bool operator==(const FileHeader&, const FileHeader&) = default;
};

/// Per level: where its page index is, and how many payload bytes the level holds.
struct LevelRecord {
  BlockRef page_index;         ///< pages_x * pages_y PageRefs; length 0 when all tiles empty
  uint64_t payload_bytes = 0;  ///< sum of the level's payload lengths (statistics)
  friend bool operator==(const LevelRecord&, const LevelRecord&) = default;
};

/// Per image: geometry and its level records.
struct ImageRecord {
  ImageInfo info;  ///< name is not stored here but in the metadata
  std::vector<LevelRecord> levels;
};

std::vector<uint8_t> encodeHeader(const FileHeader& header);
/// Checks magic, version, checksum, reserved fields and bounds. `name` prefixes messages.
Result<FileHeader> decodeHeader(std::span<const uint8_t> bytes, const std::string& name);

std::vector<uint8_t> encodeRootDirectory(const std::vector<ImageRecord>& images);
/// The minor version a file holding `images` is written as: kSampleTypeMinorVersion when an
/// image's samples are not 8-bit, so that 8-bit archives stay byte-identical.
uint16_t minorVersionFor(std::span<const ImageRecord> images);
/// Image-record byte 15 (docs/format.md, "Sample types"): u8 in files before minor 2; an
/// unknown value is kUnsupported naming `what`.
Result<SampleType> decodeSampleType(uint8_t value, const FileHeader& header,
                                    const std::string& what);
/// Decodes `image_count` image records; checks every field's bounds, that the level count
/// matches the geometry and that page-index lengths match the tile grid. Block offsets are
/// checked against `file_bytes` and `header_region_bytes`.
Result<std::vector<ImageRecord>> decodeRootDirectory(std::span<const uint8_t> bytes,
                                                     const FileHeader& header,
                                                     const std::string& name);

/// Pages across and down for a level: ceil(tiles / 2^page_tiles_log2).
uint32_t pagesX(const ImageInfo& info, uint32_t level);
uint32_t pagesY(const ImageInfo& info, uint32_t level);

/// Validates geometry fields shared by the builder and the reader; `what` prefixes messages.
Result<void> validateImageInfo(const ImageInfo& info, const std::string& what);

}  // namespace tessera::detail
