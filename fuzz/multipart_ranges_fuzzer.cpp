// Fuzzes the HTTP byte source's multipart/byteranges parser (src/stream/multipart_ranges.cpp).
// Input: a Content-Type value, a newline, then the body. Checks that every part's data lies
// inside the body and that the canonical body made of what was parsed parses back to the same
// ranges and bytes.
#include <string>
#include <string_view>
#include <vector>

#include <fmt/format.h>

#include "format_fuzz_input.h"
#include "multipart_ranges.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace tessera;
  const std::string_view input(reinterpret_cast<const char*>(data), size);
  const size_t newline = input.find('\n');
  if (newline == std::string_view::npos) return 0;
  std::string boundary;
  if (!detail::multipartBoundary(input.substr(0, newline), boundary)) return 0;
  const std::span<const uint8_t> body(data + newline + 1, size - newline - 1);
  std::vector<detail::MultipartPart> parts;
  if (!detail::parseMultipartByteranges(body, boundary, parts).empty()) return 0;
  if (parts.empty()) fuzz::die("multipart_ranges_fuzzer", "accepted a body without parts");
  std::string canonical;
  for (const detail::MultipartPart& part : parts) {
    if (!part.range.has_range || part.range.first > part.range.last)
      fuzz::die("multipart_ranges_fuzzer", "a part without an ordered range");
    if (part.data_offset > body.size() ||
        part.range.last - part.range.first >= body.size() - part.data_offset)
      fuzz::die("multipart_ranges_fuzzer", "a part's data past the body");
    canonical += fmt::format("--{}\r\nContent-Range: bytes {}-{}/*\r\n\r\n", boundary,
                             part.range.first, part.range.last);
    canonical.append(reinterpret_cast<const char*>(body.data()) + part.data_offset,
                     size_t(part.range.last - part.range.first) + 1);
    canonical += "\r\n";
  }
  canonical += fmt::format("--{}--\r\n", boundary);
  std::vector<detail::MultipartPart> again;
  const std::span<const uint8_t> canonical_bytes(reinterpret_cast<const uint8_t*>(canonical.data()),
                                                 canonical.size());
  if (!detail::parseMultipartByteranges(canonical_bytes, boundary, again).empty() ||
      again.size() != parts.size())
    fuzz::die("multipart_ranges_fuzzer", "the canonical body does not parse");
  for (size_t i = 0; i < parts.size(); ++i) {
    const size_t length = size_t(parts[i].range.last - parts[i].range.first) + 1;
    if (again[i].range.first != parts[i].range.first ||
        again[i].range.last != parts[i].range.last ||
        canonical_bytes.subspan(again[i].data_offset, length).size() != length ||
        !std::equal(body.begin() + long(parts[i].data_offset),
                    body.begin() + long(parts[i].data_offset + length),
                    canonical_bytes.begin() + long(again[i].data_offset)))
      fuzz::die("multipart_ranges_fuzzer", "the canonical body parses differently");
  }
  return 0;
}
