// Fuzzes the Range header parser (src/serve/byte_ranges.cpp). Input: one byte of max_ranges,
// four bytes (little-endian) of representation size, then the header text. Checks that a
// satisfiable answer never sends a byte outside the representation or the same byte twice.
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string_view>
#include <vector>

#include "serve/byte_ranges.h"

namespace {

[[noreturn]] void die(const char* what) {
  std::fprintf(stderr, "range_header_fuzzer: %s\n", what);
  std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 5) return 0;
  const uint32_t max_ranges = 1 + data[0] % 64;
  const uint64_t representation = uint64_t(data[1]) | uint64_t(data[2]) << 8 |
                                  uint64_t(data[3]) << 16 | uint64_t(data[4]) << 24;
  std::string_view header(reinterpret_cast<const char*>(data + 5), size - 5);
  tessera::detail::RangeRequest request =
      tessera::detail::parseRangeHeader(header, representation, max_ranges);
  if (request.verdict != tessera::detail::RangeVerdict::kSatisfiable) {
    if (!request.ranges.empty()) die("ranges without a satisfiable verdict");
    return 0;
  }
  if (request.ranges.empty()) die("satisfiable without ranges");
  if (request.ranges.size() > max_ranges) die("more ranges than allowed");
  std::vector<tessera::detail::ResolvedRange> sorted = request.ranges;
  std::sort(sorted.begin(), sorted.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  uint64_t total = 0;
  for (size_t i = 0; i < sorted.size(); ++i) {
    const auto& range = sorted[i];
    if (range.length == 0) die("empty range");
    if (range.first >= representation || range.length > representation - range.first)
      die("range outside the representation");
    if (i > 0 && sorted[i - 1].first + sorted[i - 1].length >= range.first)
      die("overlapping or touching ranges left uncoalesced");
    total += range.length;
  }
  if (total > representation) die("more bytes than the representation");
  return 0;
}
