#include "scanline_reader.h"

#include <fmt/format.h>

#include <tessera/check.h>

namespace tessera::detail {

Result<void> ScanlineReader::readRows(uint32_t rows, std::span<uint8_t> out) {
  const size_t row_bytes = size_t(info_.width_px) * info_.channels * sampleBytes(info_.sample_type);
  TESSERA_CHECK(rows > 0 && rows <= info_.height_px - next_row_)
      << path_ << ": readRows(" << rows << ") at row " << next_row_ << " of " << info_.height_px;
  TESSERA_CHECK(out.size() >= rows * row_bytes) << path_ << ": output span too small";
  if (!failure_.empty()) return fail(ErrorCode::kCorrupt, failure_);
  for (uint32_t r = 0; r < rows; ++r) {
    if (!decodeRow(out.data() + r * row_bytes)) {
      failure_ = fmt::format("{}: row {}: truncated or corrupt data ({})", path_, next_row_,
                             decoderMessage());
      return fail(ErrorCode::kCorrupt, failure_);
    }
    ++next_row_;
  }
  if (next_row_ == info_.height_px && !finishDecoding()) {
    failure_ = fmt::format("{}: after the last row: truncated or corrupt data ({})", path_,
                           decoderMessage());
    return fail(ErrorCode::kCorrupt, failure_);
  }
  return {};
}

}  // namespace tessera::detail
