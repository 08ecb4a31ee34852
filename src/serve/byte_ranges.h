#pragma once
// The Range header's byte-range-set grammar (RFC 9110, section 14.1.2) resolved against a
// representation's size. Pure: text in, ranges out.

#include <cstdint>
#include <string_view>
#include <vector>

namespace tessera::detail {

/// A resolved range: bytes [first, first + length) of the representation; length >= 1.
struct ResolvedRange {
  uint64_t first = 0;
  uint64_t length = 0;
  friend bool operator==(const ResolvedRange&, const ResolvedRange&) = default;
};

/// What to do with a Range header.
enum class RangeVerdict {
  kIgnore,         ///< not a bytes range or syntactically invalid: send the whole (200)
  kSatisfiable,    ///< send `ranges` (206)
  kUnsatisfiable,  ///< no range overlaps the representation (416)
  kTooManyRanges,  ///< more than the allowed number of ranges (416)
};

struct RangeRequest {
  RangeVerdict verdict = RangeVerdict::kIgnore;
  /// For kSatisfiable: the satisfiable ranges in request order, except that ranges that
  /// overlap or touch are coalesced into one (in ascending order), so no byte is sent twice
  /// and the response never exceeds the representation's size plus part headers.
  std::vector<ResolvedRange> ranges;
};

/// Parses `header` (the Range field value) for a representation of `size_bytes` bytes. At most
/// `max_ranges` range specs are accepted (counted before coalescing). Strict: digits only, no
/// signs, at most 19 digits per number, optional whitespace only around commas.
RangeRequest parseRangeHeader(std::string_view header, uint64_t size_bytes, uint32_t max_ranges);

}  // namespace tessera::detail
