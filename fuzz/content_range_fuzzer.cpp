// Fuzzes the HTTP byte source's Content-Range parser (src/stream/content_range.cpp). Input: the
// header's text. Checks that an accepted range is ordered and that the canonical text of what
// was parsed parses back to the same values.
#include <string>

#include <fmt/format.h>

#include "content_range.h"
#include "format_fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace tessera;
  const std::string header(reinterpret_cast<const char*>(data), size);
  detail::ContentRange range;
  if (!detail::parseContentRange(header, range)) return 0;
  if (range.has_range && range.first > range.last)
    fuzz::die("content_range_fuzzer", "first > last");
  if (!range.has_range && !range.has_total) fuzz::die("content_range_fuzzer", "nothing parsed");
  const std::string canonical = fmt::format(
      "bytes {}/{}", range.has_range ? fmt::format("{}-{}", range.first, range.last) : "*",
      range.has_total ? std::to_string(range.total) : "*");
  detail::ContentRange again;
  if (!detail::parseContentRange(canonical, again) || again.has_range != range.has_range ||
      again.first != range.first || again.last != range.last ||
      again.has_total != range.has_total || again.total != range.total)
    fuzz::die("content_range_fuzzer", "the canonical text parses differently");
  return 0;
}
