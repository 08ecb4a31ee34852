#include "content_range.h"

#include <charconv>
#include <string_view>
#include <system_error>

namespace tessera::detail {

namespace {

bool startsWithBytesUnit(std::string_view text) {
  static constexpr std::string_view kUnit = "bytes ";
  if (text.size() < kUnit.size()) return false;
  for (size_t i = 0; i < kUnit.size(); ++i) {
    const char c = text[i];
    if ((c >= 'A' && c <= 'Z' ? char(c - 'A' + 'a') : c) != kUnit[i]) return false;
  }
  return true;
}

}  // namespace

bool parseHttpUint(std::string_view text, uint64_t& out) {
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), out);
  return error == std::errc() && end == text.data() + text.size();
}

bool parseContentRange(const std::string& header, ContentRange& out) {
  std::string_view text = header;
  if (!startsWithBytesUnit(text)) return false;
  text.remove_prefix(6);
  const size_t slash = text.find('/');
  if (slash == std::string_view::npos) return false;
  std::string_view range = text.substr(0, slash), total = text.substr(slash + 1);
  if (total == "*") {
    out.has_total = false;
  } else {
    if (!parseHttpUint(total, out.total)) return false;
    out.has_total = true;
  }
  if (range == "*") {
    out.has_range = false;
    return out.has_total;
  }
  const size_t dash = range.find('-');
  if (dash == std::string_view::npos) return false;
  if (!parseHttpUint(range.substr(0, dash), out.first) ||
      !parseHttpUint(range.substr(dash + 1), out.last))
    return false;
  out.has_range = out.first <= out.last;
  return out.has_range;
}

}  // namespace tessera::detail
