#pragma once
// The section table of a version 1.1 archive (docs/format.md, "Section table"): header bytes
// 80..103 reference a small table of {kind, BlockRef} entries, one per optional part of the
// file (a scene, a procedural directory, ...), so several 1.1 features share the one reference
// that 1.0 left reserved. Pure: bytes in, structs out.

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <tessera/result.h>

#include "format/header.h"

namespace tessera::detail {

/// The minor version that gives header bytes 80..103 their meaning (the section table).
inline constexpr uint16_t kSectionsVersionMinor = 1;
/// Where the section table's BlockRef sits in the 128-byte header (reserved in 1.0).
inline constexpr uint32_t kSectionTableRefOffset = 80;
/// One entry: kind (u32), reserved (u32, zero), BlockRef (offset, length, checksum; u64 each).
inline constexpr uint32_t kSectionEntryBytes = 32;
/// Far more kinds than the format defines; bounds what a hostile table makes a reader parse.
inline constexpr uint32_t kMaxSections = 64;

/// Kinds the format defines. Kind 0 is invalid; readers skip kinds they do not know.
enum class SectionKind : uint32_t {
  kScene = 1,       ///< the 128-byte scene directory ("Scenes")
  kProcedural = 2,  ///< the procedural directory ("Procedural tiles")
  /// A scene's average coverage hints ("Coverage hints"); only beside a kScene section.
  kCoverageHints = 3,
};

/// One section: its kind (any non-zero u32, known or not) and where its first block lives.
struct SectionEntry {
  uint32_t kind = 0;  ///< != 0; unique within a table
  BlockRef block;     ///< length > 0, inside the file, at or after byte 128
  friend bool operator==(const SectionEntry&, const SectionEntry&) = default;
};

/// The table's bytes: 32 bytes per entry, in the given order. Entries must be valid (checked).
std::vector<uint8_t> encodeSectionTable(std::span<const SectionEntry> entries);
/// Decodes a table already checked against its BlockRef's checksum. Rejects (kCorrupt) a length
/// that is not 32 n with 1 <= n <= kMaxSections, kind 0, non-zero reserved bytes, a duplicate
/// kind and a block outside [128, header.file_bytes) or of length 0. Unknown kinds are kept
/// (so the table re-encodes to its bytes); readers look up the kinds they know with
/// findSection and skip the rest. `name` prefixes messages.
Result<std::vector<SectionEntry>> decodeSectionTable(std::span<const uint8_t> bytes,
                                                     const FileHeader& header,
                                                     const std::string& name);
/// The block of `kind`, or a BlockRef of length 0 when the table has none.
BlockRef findSection(std::span<const SectionEntry> entries, SectionKind kind);

/// Writes the section table's reference into an encoded 128-byte header (bytes 80..103), sets
/// its minor version to 1 and recomputes its checksum.
void stampSectionTableRef(std::span<uint8_t> header_bytes, const BlockRef& table);
/// The section table's reference in the bytes of a header that decodeHeader accepted: length 0
/// for a 1.0 file or a 1.1 file without sections. For minor 1, rejects (kCorrupt) non-zero
/// reserved bytes 104..119, an empty reference with an offset or checksum, a table outside the
/// file and a length that is no whole number of entries. Minors above 1 are read the same way
/// and their reserved bytes ignored.
Result<BlockRef> decodeSectionTableRef(std::span<const uint8_t> header_bytes,
                                       const FileHeader& header, const std::string& name);

}  // namespace tessera::detail
