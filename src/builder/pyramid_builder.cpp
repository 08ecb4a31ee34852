#include "pyramid_builder.h"

#include <algorithm>
#include <cstring>

#include <fmt/format.h>

#include "builder/downsample.h"
#include "uninitialized_buffer.h"

namespace tessera::detail {

// One level's band: a ring of rows. When tile row r is announced the ring holds rows
// [r*t - b, (r+1)*t + b), and the next announcement needs rows from (r+1)*t - b on, so
// t + 2b slots never overwrite a row still needed (a row y replaces y - t - 2b). With a sink
// that cuts later, the first row after tile row r's announcement replaces a row r needs, so
// the builder waits there until r is cut: for the last few queued tiles, while the encoders
// are busy. The ring is not written ahead of its rows, so its memory arrives with them.
struct PyramidBuilder::Level final : LevelRows {
  UninitializedBuffer ring;
  uint32_t ring_rows = 0;
  size_t row_bytes = 0;
  uint32_t received = 0;
  uint32_t next_tile_row = 0;
  uint32_t tile_rows = 0;

  const uint8_t* row(uint32_t y) const override {
    return ring.data() + size_t(y % ring_rows) * row_bytes;
  }
  uint8_t* mutableRow(uint32_t y) { return ring.data() + size_t(y % ring_rows) * row_bytes; }
};

PyramidBuilder::PyramidBuilder(const ImageInfo& info, TileSink& sink, bool floor_average)
    : info_(info), sink_(sink), floor_average_(floor_average), cuts_later_(sink.cutsLater()) {
  TESSERA_CHECK(!floor_average || !info.srgb_downsample) << "floor average is in sRGB codes only";
  for (uint32_t l = 0; l < info.level_count; ++l) {
    auto level = std::make_unique<Level>();
    level->width_px = info.levelWidthPx(l);
    level->height_px = info.levelHeightPx(l);
    level->channels = info.channels;
    level->sample_type = info.sample_type;
    level->row_bytes = size_t(level->width_px) * info.texelBytes();
    level->ring_rows = std::min(level->height_px, info.tile_size_px + 2 * info.border_px);
    level->ring.resize(level->row_bytes * level->ring_rows);
    level->tile_rows = info.tilesY(l);
    levels_.push_back(std::move(level));
  }
}

PyramidBuilder::~PyramidBuilder() {
  if (!cuts_later_) return;
  for (uint32_t l = 0; l < levels_.size(); ++l)
    if (levels_[l]->next_tile_row > 0) sink_.awaitCut(l, levels_[l]->next_tile_row - 1);
}

void PyramidBuilder::reuseSlots(uint32_t level_index, uint32_t first_row, uint32_t count) {
  const Level& level = *levels_[level_index];
  const uint64_t last_row = uint64_t(first_row) + count - 1;
  if (!cuts_later_ || count == 0 || last_row < level.ring_rows || level.next_tile_row == 0) return;
  // The rows replaced end at last_row - ring_rows; tile row r needs rows from r * t - b on.
  const uint64_t replaced = last_row - level.ring_rows;
  const uint64_t needing = (replaced + info_.border_px) / info_.tile_size_px;
  sink_.awaitCut(level_index, uint32_t(std::min<uint64_t>(needing, level.next_tile_row - 1)));
}

uint32_t PyramidBuilder::rowsReceived() const {
  return levels_[0]->received;
}

Result<void> PyramidBuilder::addRows(const uint8_t* rows, uint32_t count) {
  const size_t row_bytes = levels_[0]->row_bytes;
  for (uint32_t i = 0; i < count; ++i) TESSERA_TRY(addRow(0, rows + i * row_bytes));
  return {};
}

std::span<uint8_t> PyramidBuilder::rowsToFill(uint32_t max_rows) {
  Level& level = *levels_[0];
  const uint32_t y = level.received;
  if (y >= level.height_px || max_rows == 0) return {};
  uint32_t rows = std::min(max_rows, level.height_px - y);
  rows = std::min(rows, level.ring_rows - y % level.ring_rows);
  // Writing past the row that completes the next tile row would overwrite rows that tile row
  // still needs (a row y replaces y - ring_rows), and, from an odd row on, writing ring_rows rows
  // would overwrite the top of the first pair.
  if (level.next_tile_row < level.tile_rows) {
    const uint64_t last_needed = std::min<uint64_t>(
        level.height_px, uint64_t(level.next_tile_row + 1) * info_.tile_size_px + info_.border_px);
    rows = uint32_t(std::min<uint64_t>(rows, std::max<uint64_t>(last_needed, y + 1) - y));
  }
  if ((y & 1) == 1) rows = std::min(rows, std::max(1u, level.ring_rows - 1));
  reuseSlots(0, y, rows);
  offered_rows_ = rows;
  return {level.mutableRow(y), size_t(rows) * level.row_bytes};
}

Result<void> PyramidBuilder::commitRows(uint32_t count) {
  TESSERA_CHECK(count <= offered_rows_)
      << "committing " << count << " rows, " << offered_rows_ << " offered";
  offered_rows_ = 0;
  for (uint32_t i = 0; i < count; ++i) TESSERA_TRY(rowArrived(0));
  return {};
}

Result<void> PyramidBuilder::addRow(uint32_t level_index, const uint8_t* row) {
  Level& level = *levels_[level_index];
  TESSERA_CHECK(level.received < level.height_px) << "more rows than the level has";
  reuseSlots(level_index, level.received, 1);
  std::memcpy(level.mutableRow(level.received), row, level.row_bytes);
  return rowArrived(level_index);
}

Result<void> PyramidBuilder::rowArrived(uint32_t level_index) {
  Level& level = *levels_[level_index];
  TESSERA_CHECK(level.received < level.height_px) << "more rows than the level has";
  const uint32_t y = level.received++;

  if (level_index + 1 < levels_.size()) {
    const bool pair_complete = (y & 1) == 1;
    const bool odd_last_row = (y & 1) == 0 && y + 1 == level.height_px;
    if (pair_complete || odd_last_row) {
      // Averaged straight into the next level's band: the slot it replaces is no longer needed
      // there, exactly as when a row is copied in.
      Level& next = *levels_[level_index + 1];
      TESSERA_CHECK(next.received < next.height_px) << "more rows than the level has";
      reuseSlots(level_index + 1, next.received, 1);
      uint8_t* target = next.mutableRow(next.received);
      const uint8_t* top = level.row(pair_complete ? y - 1 : y);
      if (info_.sample_type != SampleType::kU8)
        downsampleRowPairWide(top, level.row(y), level.width_px, info_.channels, info_.sample_type,
                              target);
      else if (floor_average_)
        downsampleRowPairFloor(top, level.row(y), level.width_px, info_.channels, target);
      else
        downsampleRowPair(top, level.row(y), level.width_px, info_.channels, info_.srgb_downsample,
                          target);
      TESSERA_TRY(rowArrived(level_index + 1));
    }
  }

  const uint32_t t = info_.tile_size_px, b = info_.border_px;
  while (level.next_tile_row < level.tile_rows) {
    uint64_t last_needed =
        std::min<uint64_t>(level.height_px, uint64_t(level.next_tile_row + 1) * t + b);
    if (level.received < last_needed) break;
    TESSERA_TRY(sink_.tileRowReady(level_index, level.next_tile_row, level));
    ++level.next_tile_row;
  }
  return {};
}

Result<void> PyramidBuilder::finish() {
  for (uint32_t l = 0; l < levels_.size(); ++l) {
    const Level& level = *levels_[l];
    if (level.received != level.height_px || level.next_tile_row != level.tile_rows)
      return fail(
          ErrorCode::kInternal,
          fmt::format("pyramid level {} incomplete: {} of {} rows, {} of {} tile rows", l,
                      level.received, level.height_px, level.next_tile_row, level.tile_rows));
  }
  return {};
}

}  // namespace tessera::detail
