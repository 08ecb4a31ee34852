// A mosaic of image files placed on a grid, read as one image (docs/builder.md, "Image
// grids"): "grid:COLSxROWS:PATTERN", the file at column c and row r being PATTERN with {col}
// and {row} replaced by c and r. Slide scanners and satellite pipelines deliver such tile sets.
#include "grid_reader.h"

#include <algorithm>
#include <charconv>
#include <cstring>

#include <fmt/format.h>

#include "file_reader.h"

namespace tessera::detail {

namespace {

/// Most files in one grid: each is checked at open, a bounded number are open at once.
constexpr uint64_t kMaxGridFiles = uint64_t(1) << 20;

bool parseSide(std::string_view text, uint32_t& value) {
  if (text.empty()) return false;
  auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  return error == std::errc() && end == text.data() + text.size() && value > 0;
}

std::string replaceAll(std::string text, std::string_view key, const std::string& value) {
  for (size_t at = text.find(key); at != std::string::npos; at = text.find(key, at + value.size()))
    text.replace(at, key.size(), value);
  return text;
}

/// Reads the grid's files one row of files at a time: a band opens only the files it meets,
/// and the row before is closed first, so at most COLS files are open.
class GridReader final : public BandReader {
 public:
  explicit GridReader(GridSpec spec) : spec_(std::move(spec)) {}

  Result<void> open();
  const SourceInfo& info() const override { return info_; }
  Result<void> readRows(uint32_t rows, std::span<uint8_t> out) override;
  Result<void> skipRows(uint32_t rows) override;
  uint64_t storedBytesRead() const override {
    uint64_t bytes = closed_bytes_read_;
    for (const auto& reader : row_readers_) bytes += reader->storedBytesRead();
    return bytes;
  }

 private:
  /// Opens the files of grid row `row` (closing the others), each at `row_offset` rows down.
  Result<void> openRow(uint32_t row, uint32_t row_offset);
  /// The first file's geometry, which every file must share.
  Result<void> checkFile(const std::string& path, const SourceInfo& file) const;

  GridSpec spec_;
  SourceInfo info_;
  SourceInfo file_info_;  // of file (0, 0)
  std::vector<std::unique_ptr<BandReader>> row_readers_;
  uint32_t open_row_ = UINT32_MAX;
  uint32_t next_row_ = 0;
  uint64_t closed_bytes_read_ = 0;
  std::vector<uint8_t> piece_;  // rows of one file, before they are placed
};

Result<void> GridReader::checkFile(const std::string& path, const SourceInfo& file) const {
  // A file that does not match is bad input, as a damaged one is (exit 1, docs/cli.md).
  if (file.width_px != file_info_.width_px || file.height_px != file_info_.height_px ||
      file.channels != file_info_.channels || file.sample_type != file_info_.sample_type)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: {}x{} px, {} channel(s), {} samples; the grid's files must all "
                            "match {} ({}x{} px, {} channel(s), {} samples)",
                            path, file.width_px, file.height_px, file.channels,
                            sampleTypeName(file.sample_type), spec_.path(0, 0), file_info_.width_px,
                            file_info_.height_px, file_info_.channels,
                            sampleTypeName(file_info_.sample_type)));
  return {};
}

Result<void> GridReader::open() {
  {
    TESSERA_ASSIGN_OR_RETURN(std::unique_ptr<BandReader> first, openBandReader(spec_.path(0, 0)));
    file_info_ = first->info();
  }
  // Every file is opened once here (its header only) and closed again, so that a missing or
  // mismatched file fails the build before anything is written.
  for (uint32_t row = 0; row < spec_.rows; ++row) {
    for (uint32_t column = 0; column < spec_.columns; ++column) {
      if (row == 0 && column == 0) continue;
      const std::string path = spec_.path(column, row);
      TESSERA_ASSIGN_OR_RETURN(std::unique_ptr<BandReader> file, openBandReader(path));
      TESSERA_TRY(checkFile(path, file->info()));
    }
  }
  const uint64_t width = uint64_t(file_info_.width_px) * spec_.columns;
  const uint64_t height = uint64_t(file_info_.height_px) * spec_.rows;
  TESSERA_TRY(checkSourceDimensions(spec_.text, width, height));
  info_ = file_info_;
  info_.width_px = uint32_t(width);
  info_.height_px = uint32_t(height);
  info_.natural_band_rows = std::min(file_info_.natural_band_rows, file_info_.height_px);
  info_.buffer_bytes = uint64_t(spec_.columns) * file_info_.buffer_bytes +
                       uint64_t(file_info_.width_px) * info_.natural_band_rows *
                           file_info_.channels * sampleBytes(file_info_.sample_type);
  info_.format = "grid";
  info_.metadata = {{"grid",
                     {{"columns", spec_.columns},
                      {"rows", spec_.rows},
                      {"pattern", spec_.pattern},
                      {"file_format", file_info_.format},
                      {"file_width", file_info_.width_px},
                      {"file_height", file_info_.height_px}}}};
  return {};
}

Result<void> GridReader::openRow(uint32_t row, uint32_t row_offset) {
  for (const auto& reader : row_readers_) closed_bytes_read_ += reader->storedBytesRead();
  row_readers_.clear();
  open_row_ = row;
  for (uint32_t column = 0; column < spec_.columns; ++column) {
    const std::string path = spec_.path(column, row);
    TESSERA_ASSIGN_OR_RETURN(std::unique_ptr<BandReader> file, openBandReader(path));
    TESSERA_TRY(checkFile(path, file->info()));  // replaced since open()?
    if (row_offset > 0) TESSERA_TRY(file->skipRows(row_offset));
    row_readers_.push_back(std::move(file));
  }
  return {};
}

Result<void> GridReader::readRows(uint32_t rows, std::span<uint8_t> out) {
  const size_t pixel_bytes = size_t(info_.channels) * sampleBytes(info_.sample_type);
  const size_t row_bytes = size_t(info_.width_px) * pixel_bytes;
  const size_t file_row_bytes = size_t(file_info_.width_px) * pixel_bytes;
  TESSERA_CHECK(rows > 0 && rows <= info_.height_px - next_row_)
      << spec_.text << ": readRows(" << rows << ") at row " << next_row_;
  TESSERA_CHECK(out.size() >= rows * row_bytes) << spec_.text << ": output span too small";
  for (uint32_t done = 0; done < rows;) {
    const uint32_t grid_row = next_row_ / file_info_.height_px;
    const uint32_t offset = next_row_ % file_info_.height_px;
    if (grid_row != open_row_) TESSERA_TRY(openRow(grid_row, offset));
    const uint32_t take = std::min(rows - done, file_info_.height_px - offset);
    piece_.resize(file_row_bytes * take);
    for (uint32_t column = 0; column < spec_.columns; ++column) {
      TESSERA_TRY(row_readers_[column]->readRows(take, piece_));
      for (uint32_t y = 0; y < take; ++y)
        std::memcpy(out.data() + (done + y) * row_bytes + column * file_row_bytes,
                    piece_.data() + y * file_row_bytes, file_row_bytes);
    }
    done += take;
    next_row_ += take;
  }
  return {};
}

Result<void> GridReader::skipRows(uint32_t rows) {
  TESSERA_CHECK(rows <= info_.height_px - next_row_)
      << spec_.text << ": skipRows(" << rows << ") at row " << next_row_;
  const uint32_t target = next_row_ + rows;
  // Within the open row of files, each skips (a TIFF seeks); rows of files wholly above the
  // target are never opened.
  if (rows > 0 && open_row_ == next_row_ / file_info_.height_px &&
      target / file_info_.height_px == open_row_) {
    for (const auto& reader : row_readers_) TESSERA_TRY(reader->skipRows(rows));
  } else if (rows > 0) {
    for (const auto& reader : row_readers_) closed_bytes_read_ += reader->storedBytesRead();
    row_readers_.clear();
    open_row_ = UINT32_MAX;
  }
  next_row_ = target;
  return {};
}

}  // namespace

std::string GridSpec::path(uint32_t column, uint32_t row) const {
  return replaceAll(replaceAll(pattern, "{col}", std::to_string(column)), "{row}",
                    std::to_string(row));
}

Result<GridSpec> parseGridSpec(const std::string& text) {
  GridSpec spec;
  spec.text = text;
  const std::string_view body = std::string_view(text).substr(kGridPrefix.size());
  const size_t x = body.find('x');
  const size_t colon = body.find(':');
  if (!text.starts_with(kGridPrefix) || x == std::string_view::npos ||
      colon == std::string_view::npos || x > colon || !parseSide(body.substr(0, x), spec.columns) ||
      !parseSide(body.substr(x + 1, colon - x - 1), spec.rows))
    return fail(
        ErrorCode::kInvalidArgument,
        fmt::format("{}: want grid:COLSxROWS:PATTERN, e.g. grid:4x3:scan_{{col}}_{{row}}.tif",
                    text));
  spec.pattern = std::string(body.substr(colon + 1));
  if (spec.pattern.find("{col}") == std::string::npos ||
      spec.pattern.find("{row}") == std::string::npos)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: the pattern must name both {{col}} and {{row}}", text));
  if (uint64_t(spec.columns) * spec.rows > kMaxGridFiles)
    return fail(ErrorCode::kTooLarge,
                fmt::format("{}: {} files, over the limit of {}", text,
                            uint64_t(spec.columns) * spec.rows, kMaxGridFiles));
  return spec;
}

Result<std::unique_ptr<BandReader>> openGridReader(const std::string& text) {
  TESSERA_ASSIGN_OR_RETURN(GridSpec spec, parseGridSpec(text));
  auto reader = std::make_unique<GridReader>(std::move(spec));
  TESSERA_TRY(reader->open());
  return std::unique_ptr<BandReader>(std::move(reader));
}

}  // namespace tessera::detail
