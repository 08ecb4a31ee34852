// Fuzzes the page-index decoder (docs/format.md, "Page index"), whole and one reference at a
// time as a reader of terapixel levels does. Input: an image's geometry
// (format_fuzz_input.h), the file size (u64), then the index's bytes. Checks that both ways
// agree and that an accepted index is canonical.
#include <algorithm>

#include "format/directory.h"
#include "format_fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace tessera;
  fuzz::InputReader reader({data, size});
  if (!reader.has(fuzz::kGeometryInputBytes + 8)) return 0;
  const fuzz::GeometryInput geometry = fuzz::readGeometry(reader);
  const uint64_t file_bytes = reader.take(8);
  const ImageInfo& info = geometry.info;
  if (!detail::validateImageInfo(info, "fuzz") || geometry.level >= info.level_count) return 0;
  const std::span<const uint8_t> bytes = reader.rest();
  Result<std::vector<detail::PageRef>> pages =
      detail::decodePageIndex(bytes, info, geometry.level, file_bytes, "fuzz");
  if (!pages) return 0;
  for (uint32_t i = 0; i < pages->size(); ++i) {
    Result<detail::PageRef> one = detail::decodePageRef(
        bytes.subspan(size_t(i) * detail::kPageRefBytes, detail::kPageRefBytes), info,
        geometry.level, i, file_bytes, "fuzz");
    if (!one || !(*one == (*pages)[i]))
      fuzz::die("page_index_fuzzer", "a reference read alone differs from the whole index");
  }
  const std::vector<uint8_t> again = detail::encodePageIndex(*pages);
  if (again.size() != bytes.size() || !std::equal(again.begin(), again.end(), bytes.begin()))
    fuzz::die("page_index_fuzzer", "an accepted index does not re-encode to its bytes");
  return 0;
}
