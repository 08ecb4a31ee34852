#pragma once
// The multipart/byteranges body a server sends for a request of several ranges (RFC 9110,
// section 14.6), as the HTTP byte source reads it. Pure; fuzzed by
// fuzz/multipart_ranges_fuzzer.cpp.

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "content_range.h"

namespace tessera::detail {

/// One part of the body: its Content-Range and where its bytes start in the body. The part's
/// bytes are body[data_offset, data_offset + range.last - range.first + 1).
struct MultipartPart {
  ContentRange range;  ///< has_range is always true
  size_t data_offset = 0;
};

/// The boundary of a Content-Type `multipart/byteranges; boundary=B` (B may be quoted; the
/// type and parameter names are case-insensitive). False for another type or a boundary that
/// is empty or longer than 70 characters (RFC 2046).
bool multipartBoundary(std::string_view content_type, std::string& boundary);

/// Splits `body` into its parts. Each part needs a Content-Range with a range; its data is
/// exactly that many bytes, followed by a line break and the next delimiter; the close
/// delimiter ends the body (a preamble before the first delimiter and an epilogue after the
/// last are ignored). Line breaks may be CRLF or a bare LF. Returns an empty string on
/// success, else what is wrong (for the error message). Either way `parts` holds the parts
/// read whole (their data lies inside the body and a delimiter follows it); on a failure these
/// are the ones before the fault.
std::string parseMultipartByteranges(std::span<const uint8_t> body, std::string_view boundary,
                                     std::vector<MultipartPart>& parts);

}  // namespace tessera::detail
