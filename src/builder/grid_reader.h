#pragma once
// Image files placed on a grid, read as one image: "grid:COLSxROWS:PATTERN"
// (docs/builder.md, "Image grids").

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include <tessera/result.h>

#include "band_reader.h"

namespace tessera::detail {

inline constexpr std::string_view kGridPrefix = "grid:";

/// A parsed "grid:COLSxROWS:PATTERN".
struct GridSpec {
  std::string text;  ///< as given, for messages
  uint32_t columns = 0, rows = 0;
  std::string pattern;  ///< with {col} and {row}, counted from 0
  /// The file at `column`, `row`.
  std::string path(uint32_t column, uint32_t row) const;
};

/// Parses `text`; fails naming it when it is not COLSxROWS (each at least 1) and a pattern
/// holding both {col} and {row}, or names over a million files.
[[nodiscard]] Result<GridSpec> parseGridSpec(const std::string& text);

/// Opens a grid: every file is checked first (present, readable, and the size, channels and
/// sample type of the file at column 0, row 0), failing naming the first that is not; then
/// bands open only the row of files they meet, so at most COLS files are open at once.
[[nodiscard]] Result<std::unique_ptr<BandReader>> openGridReader(const std::string& text);

}  // namespace tessera::detail
