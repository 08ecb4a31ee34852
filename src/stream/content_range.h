#pragma once
// The Content-Range header of a 206 or 416 answer (RFC 9110, section 14.4), as the HTTP byte
// source reads it. Pure; fuzzed by fuzz/content_range_fuzzer.cpp.

#include <cstdint>
#include <string>
#include <string_view>

namespace tessera::detail {

/// "bytes A-B/T" (T may be "*"): the range a 206 carries, or the size a 416 reports
/// ("bytes */T", has_range false).
struct ContentRange {
  bool has_range = false;
  uint64_t first = 0, last = 0;
  bool has_total = false;
  uint64_t total = 0;
};

/// An HTTP decimal number (Content-Range's positions, Retry-After's seconds): digits only, the
/// whole text, within 64 bits; no sign, no space.
bool parseHttpUint(std::string_view text, uint64_t& out);

/// Parses `header`; false for anything but the forms above (a case-insensitive "bytes " unit,
/// decimal numbers within 64 bits without sign or space, first <= last). On success a range
/// satisfies first <= last, and `total`, when present, is what the header says (checking the
/// range against it is the caller's job).
bool parseContentRange(const std::string& header, ContentRange& out);

}  // namespace tessera::detail
