#include "format/sections.h"

#include <algorithm>

#include <fmt/format.h>

#include "format/byte_io.h"
#include "format/checksum.h"

namespace tessera::detail {

namespace {

constexpr uint32_t kHeaderChecksumOffset = 120;

bool insideFile(const BlockRef& block, uint64_t file_bytes) {
  return block.offset_bytes >= kHeaderBytes && block.offset_bytes <= file_bytes &&
         block.length_bytes <= file_bytes - block.offset_bytes;
}

}  // namespace

std::vector<uint8_t> encodeSectionTable(std::span<const SectionEntry> entries) {
  TESSERA_CHECK(!entries.empty() && entries.size() <= kMaxSections)
      << "a section table holds 1.." << kMaxSections << " entries";
  std::vector<uint8_t> bytes(entries.size() * kSectionEntryBytes, 0);
  for (size_t i = 0; i < entries.size(); ++i) {
    TESSERA_CHECK(entries[i].kind != 0 && entries[i].block.length_bytes != 0)
        << "section " << i << " has kind 0 or an empty block";
    uint8_t* p = bytes.data() + i * kSectionEntryBytes;
    storeU32(p, entries[i].kind);
    storeBlockRef(p + 8, entries[i].block);
  }
  return bytes;
}

Result<std::vector<SectionEntry>> decodeSectionTable(std::span<const uint8_t> bytes,
                                                     const FileHeader& header,
                                                     const std::string& name) {
  const std::string what = name + ": section table";
  if (bytes.empty() || bytes.size() % kSectionEntryBytes != 0 ||
      bytes.size() / kSectionEntryBytes > kMaxSections)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{} of {} bytes, expected 32 n bytes with 1 <= n <= {}", what,
                            bytes.size(), kMaxSections));
  std::vector<SectionEntry> entries(bytes.size() / kSectionEntryBytes);
  for (size_t i = 0; i < entries.size(); ++i) {
    const uint8_t* p = bytes.data() + i * kSectionEntryBytes;
    SectionEntry& entry = entries[i];
    entry.kind = loadU32(p);
    entry.block = loadBlockRef(p + 8);
    if (entry.kind == 0)
      return fail(ErrorCode::kCorrupt, fmt::format("{}: entry {} has kind 0", what, i));
    if (!allZero(p + 4, 4))
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: entry {} has non-zero reserved bytes", what, i));
    if (entry.block.length_bytes == 0 || !insideFile(entry.block, header.file_bytes))
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: section of kind {} at [{}, +{}) is empty or outside the "
                              "file of {} bytes",
                              what, entry.kind, entry.block.offset_bytes, entry.block.length_bytes,
                              header.file_bytes));
    for (size_t j = 0; j < i; ++j)
      if (entries[j].kind == entry.kind)
        return fail(
            ErrorCode::kCorrupt,
            fmt::format("{}: kind {} appears twice (entries {} and {})", what, entry.kind, j, i));
  }
  return entries;
}

BlockRef findSection(std::span<const SectionEntry> entries, SectionKind kind) {
  for (const SectionEntry& entry : entries)
    if (entry.kind == uint32_t(kind)) return entry.block;
  return {};
}

void stampSectionTableRef(std::span<uint8_t> header_bytes, const BlockRef& table) {
  TESSERA_CHECK(header_bytes.size() >= kHeaderBytes) << "a header is 128 bytes";
  uint8_t* p = header_bytes.data();
  // A file already of a later minor (16-bit or float images) keeps it.
  storeU16(p + 10, std::max(loadU16(p + 10), kSectionsVersionMinor));
  storeBlockRef(p + kSectionTableRefOffset, table);
  storeU64(p + kHeaderChecksumOffset, checksum64({p, kHeaderChecksumOffset}));
}

Result<BlockRef> decodeSectionTableRef(std::span<const uint8_t> header_bytes,
                                       const FileHeader& header, const std::string& name) {
  TESSERA_CHECK(header_bytes.size() >= kHeaderBytes) << "a header is 128 bytes";
  if (header.version_minor < kSectionsVersionMinor) return BlockRef{};
  const uint8_t* p = header_bytes.data();
  if (header.version_minor == kSectionsVersionMinor && !allZero(p + 104, 16))
    return fail(ErrorCode::kCorrupt, name + ": reserved header bytes 104..119 are not zero");
  const BlockRef table = loadBlockRef(p + kSectionTableRefOffset);
  if (table.length_bytes == 0) {
    if (table.offset_bytes != 0 || table.checksum != 0)
      return fail(ErrorCode::kCorrupt,
                  name + ": section table is empty but has an offset or checksum");
    return table;
  }
  if (!insideFile(table, header.file_bytes))
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: section table [{}, +{}) outside the file of {} bytes", name,
                            table.offset_bytes, table.length_bytes, header.file_bytes));
  if (table.length_bytes % kSectionEntryBytes != 0 ||
      table.length_bytes > uint64_t(kMaxSections) * kSectionEntryBytes)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: section table of {} bytes, expected 32 n bytes with n <= {}", name,
                            table.length_bytes, kMaxSections));
  return table;
}

}  // namespace tessera::detail
