// Fuzzes the fixed header's decoder (docs/format.md, "Header"). Input: the header's bytes.
// Checks that an accepted header of a known minor version is canonical: encoding what was
// decoded gives back exactly the 128 bytes read.
#include <algorithm>

#include "format/header.h"
#include "format_fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace tessera;
  const std::span<const uint8_t> bytes(data, size);
  Result<detail::FileHeader> header = detail::decodeHeader(bytes, "fuzz");
  if (!header) {
    if (header.error().message.empty()) fuzz::die("header_fuzzer", "error without a message");
    return 0;
  }
  if (header->image_count == 0 || header->file_bytes < header->header_region_bytes)
    fuzz::die("header_fuzzer", "accepted a header outside its bounds");
  if (header->version_minor != kFormatVersionMinor) return 0;  // reserved fields may be set
  const std::vector<uint8_t> again = detail::encodeHeader(*header);
  if (!std::equal(again.begin(), again.end(), bytes.begin()))
    fuzz::die("header_fuzzer", "an accepted header does not re-encode to its bytes");
  return 0;
}
