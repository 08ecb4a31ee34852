// The band reader over a caller's RowSource (tessera/build.h): rows come from a callback, so
// the builder streams an in-memory or memory-mapped array, or a generator, like a file.

#include <algorithm>

#include <fmt/format.h>

#include <tessera/build.h>

#include "band_reader.h"
#include "file_reader.h"

namespace tessera::detail {
namespace {

/// The band height of a source that states none: the builder then reads one tile row a time
/// (bandRowsFor), the least it can.
constexpr uint32_t kDefaultBandRows = 1;

class RowSourceReader final : public BandReader {
 public:
  explicit RowSourceReader(const RowSource& source) : source_(source) {
    info_.width_px = source.width_px;
    info_.height_px = source.height_px;
    info_.channels = source.channels;
    info_.sample_type = source.sample_type;
    info_.natural_band_rows =
        std::clamp(source.band_rows ? source.band_rows : kDefaultBandRows, 1u, source.height_px);
    info_.format = "rows";
  }
  const SourceInfo& info() const override { return info_; }
  Result<void> readRows(uint32_t rows, std::span<uint8_t> out) override {
    TESSERA_CHECK(rows > 0 && rows <= info_.height_px - next_row_)
        << source_.name << ": readRows(" << rows << ") at row " << next_row_;
    Result<void> read = source_.read_rows(next_row_, rows, out);
    if (!read) {
      const Error& error = read.error();
      if (error.message.starts_with(source_.name)) return read;
      return fail(error.code, fmt::format("{}: rows {}..{}: {}", source_.name, next_row_,
                                          next_row_ + rows - 1, error.message));
    }
    next_row_ += rows;
    return {};
  }

 private:
  const RowSource& source_;
  SourceInfo info_;
  uint32_t next_row_ = 0;
};

}  // namespace

Result<std::unique_ptr<BandReader>> openRowSourceReader(const RowSource& source) {
  TESSERA_TRY(checkSourceDimensions(source.name, source.width_px, source.height_px));
  return std::unique_ptr<BandReader>(std::make_unique<RowSourceReader>(source));
}

}  // namespace tessera::detail
