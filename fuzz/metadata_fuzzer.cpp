// Fuzzes the metadata parser (docs/format.md, "Metadata"). Input: the image count (1 byte),
// then the block. Checks that an accepted block is kept as stored and names every image.
#include <algorithm>

#include "format/metadata.h"
#include "format_fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace tessera;
  fuzz::InputReader reader({data, size});
  if (!reader.has(1)) return 0;
  const size_t image_count = size_t(reader.take(1));
  const std::span<const uint8_t> bytes = reader.rest();
  Result<detail::ArchiveMetadata> metadata = detail::parseMetadata(bytes, image_count, "fuzz");
  if (!metadata) return 0;
  if (metadata->image_names.size() != image_count)
    fuzz::die("metadata_fuzzer", "not one name per image");
  // Compared as bytes: char is signed here, and a UTF-8 lead byte is not equal to itself as
  // uint8_t and as char.
  const auto* kept = reinterpret_cast<const uint8_t*>(metadata->json.data());
  if (metadata->json.size() != bytes.size() || !std::equal(bytes.begin(), bytes.end(), kept))
    fuzz::die("metadata_fuzzer", "the block is not kept as stored");
  return 0;
}
