// Fuzzes the section table's decoder (docs/format.md, "Section table"). Input: the file size
// (u64, little-endian), then the table's bytes. Checks that an accepted table is canonical
// (it re-encodes to exactly its bytes), names each kind once and keeps every block inside the
// file, and that looking up the kinds a reader knows never fails on what the decoder accepted
// except by the scene's and procedural directory's own length rules.
#include <algorithm>

#include "format/procedural.h"
#include "format/scene.h"
#include "format/sections.h"
#include "format_fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace tessera;
  fuzz::InputReader input({data, size});
  if (!input.has(8)) return 0;
  detail::FileHeader header;
  header.version_minor = detail::kSectionsVersionMinor;
  header.file_bytes = input.take(8);
  const std::span<const uint8_t> bytes = input.rest();
  Result<std::vector<detail::SectionEntry>> table =
      detail::decodeSectionTable(bytes, header, "fuzz");
  if (!table) {
    if (table.error().message.empty()) fuzz::die("section_table_fuzzer", "error without a message");
    return 0;
  }
  for (size_t i = 0; i < table->size(); ++i) {
    const detail::SectionEntry& entry = (*table)[i];
    if (entry.kind == 0 || entry.block.length_bytes == 0 ||
        entry.block.offset_bytes < detail::kHeaderBytes ||
        entry.block.offset_bytes + entry.block.length_bytes > header.file_bytes)
      fuzz::die("section_table_fuzzer", "accepted a section outside its bounds");
    for (size_t j = 0; j < i; ++j)
      if ((*table)[j].kind == entry.kind) fuzz::die("section_table_fuzzer", "accepted a duplicate");
  }
  const std::vector<uint8_t> again = detail::encodeSectionTable(*table);
  if (again.size() != bytes.size() || !std::equal(again.begin(), again.end(), bytes.begin()))
    fuzz::die("section_table_fuzzer", "an accepted table does not re-encode to its bytes");
  Result<detail::BlockRef> scene = detail::decodeSceneRef(*table, "fuzz");
  if (scene && scene->length_bytes != 0 && scene->length_bytes != detail::kSceneDirectoryBytes)
    fuzz::die("section_table_fuzzer", "accepted a scene directory of the wrong length");
  Result<detail::BlockRef> procedural = detail::decodeProceduralRef(*table, "fuzz");
  if (procedural && procedural->length_bytes > detail::kMaxMetadataBytes)
    fuzz::die("section_table_fuzzer", "accepted an oversized procedural directory");
  return 0;
}
