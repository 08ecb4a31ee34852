#include "multipart_ranges.h"

#include <fmt/format.h>

namespace tessera::detail {

namespace {

char lower(char c) {
  return c >= 'A' && c <= 'Z' ? char(c - 'A' + 'a') : c;
}

bool equalsIgnoringCase(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i)
    if (lower(a[i]) != lower(b[i])) return false;
  return true;
}

std::string_view trimmed(std::string_view text) {
  while (!text.empty() && (text.front() == ' ' || text.front() == '\t')) text.remove_prefix(1);
  while (!text.empty() && (text.back() == ' ' || text.back() == '\t')) text.remove_suffix(1);
  return text;
}

/// The line starting at `pos` without its line break; `pos` moves past the break. False when
/// no line break follows.
bool takeLine(std::string_view text, size_t& pos, std::string_view& line) {
  const size_t end = text.find('\n', pos);
  if (end == std::string_view::npos) return false;
  line = text.substr(pos, end - pos);
  if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
  pos = end + 1;
  return true;
}

/// A part's header lines up to the blank line; its Content-Range into `range`.
std::string readPartHeaders(std::string_view text, size_t& pos, ContentRange& range) {
  bool has_range = false;
  for (std::string_view line;;) {
    if (!takeLine(text, pos, line)) return "a part's headers are not terminated";
    if (line.empty()) break;
    const size_t colon = line.find(':');
    if (colon == std::string_view::npos) return "a part header without a colon";
    if (!equalsIgnoringCase(trimmed(line.substr(0, colon)), "content-range")) continue;
    if (has_range) return "a part with two Content-Range headers";
    if (!parseContentRange(std::string(trimmed(line.substr(colon + 1))), range) || !range.has_range)
      return fmt::format("a part's Content-Range \"{}\" is not a byte range",
                         trimmed(line.substr(colon + 1)));
    has_range = true;
  }
  return has_range ? "" : "a part without a Content-Range";
}

/// After a part's data: a line break, then the delimiter.
bool atDelimiterAfterData(std::string_view text, size_t& pos, std::string_view delimiter) {
  if (text.substr(pos, 2) == "\r\n")
    pos += 2;
  else if (text.substr(pos, 1) == "\n")
    pos += 1;
  else
    return false;
  return text.substr(pos, delimiter.size()) == delimiter;
}

}  // namespace

bool multipartBoundary(std::string_view content_type, std::string& boundary) {
  const size_t semicolon = content_type.find(';');
  if (!equalsIgnoringCase(trimmed(content_type.substr(0, semicolon)), "multipart/byteranges"))
    return false;
  std::string_view params =
      semicolon == std::string_view::npos ? "" : content_type.substr(semicolon + 1);
  while (!params.empty()) {
    const size_t next = params.find(';');
    const std::string_view param = trimmed(params.substr(0, next));
    params = next == std::string_view::npos ? "" : params.substr(next + 1);
    const size_t equals = param.find('=');
    if (equals == std::string_view::npos ||
        !equalsIgnoringCase(trimmed(param.substr(0, equals)), "boundary"))
      continue;
    std::string_view value = trimmed(param.substr(equals + 1));
    if (value.size() >= 2 && value.front() == '"' && value.back() == '"')
      value = value.substr(1, value.size() - 2);
    if (value.empty() || value.size() > 70) return false;
    boundary.assign(value);
    return true;
  }
  return false;
}

std::string parseMultipartByteranges(std::span<const uint8_t> body, std::string_view boundary,
                                     std::vector<MultipartPart>& parts) {
  parts.clear();
  if (boundary.empty()) return "an empty boundary";
  const std::string_view text(reinterpret_cast<const char*>(body.data()), body.size());
  const std::string delimiter = "--" + std::string(boundary);
  // The first delimiter starts the body or a line after the preamble.
  size_t pos = 0;
  if (text.substr(0, delimiter.size()) != delimiter) {
    pos = text.find("\n" + delimiter);
    if (pos == std::string_view::npos) return "no boundary delimiter in the body";
    ++pos;
  }
  for (;;) {
    pos += delimiter.size();
    if (text.substr(pos, 2) == "--") return parts.empty() ? "no parts before the close" : "";
    while (pos < text.size() && (text[pos] == ' ' || text[pos] == '\t')) ++pos;
    std::string_view rest;
    if (!takeLine(text, pos, rest) || !rest.empty())
      return "a boundary delimiter not followed by a line break";
    MultipartPart part;
    if (std::string why = readPartHeaders(text, pos, part.range); !why.empty()) return why;
    // last - first + 1 may not fit: compare without adding.
    if (part.range.last - part.range.first >= text.size() - pos)
      return fmt::format("part bytes {}-{} run past the end of the body", part.range.first,
                         part.range.last);
    part.data_offset = pos;
    pos += size_t(part.range.last - part.range.first) + 1;
    if (!atDelimiterAfterData(text, pos, delimiter))
      return fmt::format("part bytes {}-{} not followed by a boundary delimiter", part.range.first,
                         part.range.last);
    parts.push_back(part);
  }
}

}  // namespace tessera::detail
