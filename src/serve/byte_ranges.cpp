#include "byte_ranges.h"

#include <algorithm>
#include <optional>

namespace tessera::detail {

namespace {

bool isOws(char c) {
  return c == ' ' || c == '\t';
}

std::string_view trimOws(std::string_view text) {
  while (!text.empty() && isOws(text.front())) text.remove_prefix(1);
  while (!text.empty() && isOws(text.back())) text.remove_suffix(1);
  return text;
}

// 19 digits always fit in uint64_t; longer numbers are refused rather than saturated so a
// client never gets a range it did not ask for.
std::optional<uint64_t> parseDigits(std::string_view text) {
  if (text.empty() || text.size() > 19) return std::nullopt;
  uint64_t value = 0;
  for (char c : text) {
    if (c < '0' || c > '9') return std::nullopt;
    value = value * 10 + uint64_t(c - '0');
  }
  return value;
}

struct RangeSpec {
  std::optional<uint64_t> first;  // absent for a suffix range
  std::optional<uint64_t> last;   // absent for "first-"
  uint64_t suffix = 0;
};

std::optional<RangeSpec> parseSpec(std::string_view spec) {
  size_t dash = spec.find('-');
  if (dash == std::string_view::npos) return std::nullopt;
  std::string_view left = spec.substr(0, dash), right = spec.substr(dash + 1);
  RangeSpec out;
  if (left.empty()) {
    std::optional<uint64_t> suffix = parseDigits(right);
    if (!suffix) return std::nullopt;
    out.suffix = *suffix;
    return out;
  }
  out.first = parseDigits(left);
  if (!out.first) return std::nullopt;
  if (!right.empty()) {
    out.last = parseDigits(right);
    if (!out.last || *out.last < *out.first) return std::nullopt;
  }
  return out;
}

}  // namespace

RangeRequest parseRangeHeader(std::string_view header, uint64_t size_bytes, uint32_t max_ranges) {
  RangeRequest result;
  header = trimOws(header);
  constexpr std::string_view kUnit = "bytes=";
  if (header.size() < kUnit.size()) return result;
  // The range unit is case-insensitive (RFC 9110, section 14.1).
  for (size_t i = 0; i < kUnit.size(); ++i) {
    char c = header[i];
    if (c >= 'A' && c <= 'Z') c = char(c - 'A' + 'a');
    if (c != kUnit[i]) return result;
  }
  header.remove_prefix(kUnit.size());

  std::vector<RangeSpec> specs;
  while (true) {
    size_t comma = header.find(',');
    std::string_view item = trimOws(header.substr(0, comma));
    // Empty list elements are allowed by the list syntax (RFC 9110, section 5.6.1).
    if (!item.empty()) {
      std::optional<RangeSpec> spec = parseSpec(item);
      if (!spec) return result;
      if (specs.size() >= max_ranges) {
        result.verdict = RangeVerdict::kTooManyRanges;
        return result;
      }
      specs.push_back(*spec);
    }
    if (comma == std::string_view::npos) break;
    header.remove_prefix(comma + 1);
  }
  if (specs.empty()) return result;

  std::vector<ResolvedRange> ranges;
  for (const RangeSpec& spec : specs) {
    if (!spec.first) {
      if (spec.suffix == 0 || size_bytes == 0) continue;
      uint64_t length = std::min(spec.suffix, size_bytes);
      ranges.push_back({size_bytes - length, length});
      continue;
    }
    if (*spec.first >= size_bytes) continue;
    uint64_t last = spec.last ? std::min(*spec.last, size_bytes - 1) : size_bytes - 1;
    ranges.push_back({*spec.first, last - *spec.first + 1});
  }
  if (ranges.empty()) {
    result.verdict = RangeVerdict::kUnsatisfiable;
    return result;
  }

  std::vector<ResolvedRange> sorted = ranges;
  std::sort(sorted.begin(), sorted.end(),
            [](const ResolvedRange& a, const ResolvedRange& b) { return a.first < b.first; });
  bool overlapping = false;
  for (size_t i = 1; i < sorted.size(); ++i)
    if (sorted[i].first <= sorted[i - 1].first + sorted[i - 1].length) overlapping = true;
  if (overlapping) {
    std::vector<ResolvedRange> merged;
    for (const ResolvedRange& range : sorted) {
      if (!merged.empty() && range.first <= merged.back().first + merged.back().length) {
        uint64_t end =
            std::max(merged.back().first + merged.back().length, range.first + range.length);
        merged.back().length = end - merged.back().first;
      } else {
        merged.push_back(range);
      }
    }
    ranges = std::move(merged);
  }
  result.verdict = RangeVerdict::kSatisfiable;
  result.ranges = std::move(ranges);
  return result;
}

}  // namespace tessera::detail
