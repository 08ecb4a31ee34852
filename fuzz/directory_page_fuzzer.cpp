// Fuzzes the directory-page decoder (docs/format.md, "Directory pages"). Input: an image's
// geometry (format_fuzz_input.h), the file size (u64), then the page's bytes. Checks that
// every accepted entry lies inside the file and that an accepted page is canonical.
#include <algorithm>

#include "format/directory.h"
#include "format_fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace tessera;
  fuzz::InputReader reader({data, size});
  if (!reader.has(fuzz::kGeometryInputBytes + 8)) return 0;
  const fuzz::GeometryInput geometry = fuzz::readGeometry(reader);
  detail::FileHeader header;
  header.file_bytes = std::max<uint64_t>(reader.take(8), header.header_region_bytes);
  if (!detail::validateImageInfo(geometry.info, "fuzz")) return 0;
  const std::span<const uint8_t> bytes = reader.rest();
  Result<std::vector<TileEntry>> entries =
      detail::decodeTileEntries(bytes, geometry.info, header, "fuzz");
  if (!entries) return 0;
  for (const TileEntry& entry : *entries) {
    if (entry.kind != TileKind::kEncoded) continue;
    if (entry.offset_bytes < header.header_region_bytes ||
        entry.offset_bytes + entry.length_bytes > header.file_bytes)
      fuzz::die("directory_page_fuzzer", "accepted a payload outside the file");
    if (entry.length_bytes > detail::maxPayloadBytes(geometry.info))
      fuzz::die("directory_page_fuzzer", "accepted a payload longer than the bound");
  }
  const std::vector<uint8_t> again = detail::encodeTileEntries(*entries);
  if (again.size() != bytes.size() || !std::equal(again.begin(), again.end(), bytes.begin()))
    fuzz::die("directory_page_fuzzer", "an accepted page does not re-encode to its bytes");
  return 0;
}
