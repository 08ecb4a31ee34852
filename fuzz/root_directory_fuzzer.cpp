// Fuzzes the root directory's decoder (docs/format.md, "Root directory"). Input: the image
// count (1 byte, 1..8), the file size (u64), then the directory's bytes. Checks that every
// accepted image passes the geometry rules and that an accepted directory is canonical.
#include <algorithm>

#include "format/header.h"
#include "format_fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace tessera;
  fuzz::InputReader reader({data, size});
  if (!reader.has(9)) return 0;
  detail::FileHeader header;
  header.image_count = 1 + uint32_t(reader.take(1) % 8);
  header.file_bytes = reader.take(8);
  if (header.file_bytes < header.header_region_bytes)
    header.file_bytes = header.header_region_bytes;
  const std::span<const uint8_t> bytes = reader.rest();
  Result<std::vector<detail::ImageRecord>> records =
      detail::decodeRootDirectory(bytes, header, "fuzz");
  if (!records) return 0;
  if (records->size() != header.image_count) fuzz::die("root_directory_fuzzer", "image count");
  for (const detail::ImageRecord& record : *records) {
    if (!detail::validateImageInfo(record.info, "fuzz"))
      fuzz::die("root_directory_fuzzer", "accepted an image the geometry rules refuse");
    if (record.levels.size() != record.info.level_count)
      fuzz::die("root_directory_fuzzer", "level records disagree with the level count");
  }
  const std::vector<uint8_t> again = detail::encodeRootDirectory(*records);
  if (again.size() != bytes.size() || !std::equal(again.begin(), again.end(), bytes.begin()))
    fuzz::die("root_directory_fuzzer", "an accepted directory does not re-encode to its bytes");
  return 0;
}
