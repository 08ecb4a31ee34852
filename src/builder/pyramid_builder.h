#pragma once
// The streaming pyramid: level-0 rows go in top to bottom; each level keeps one band of
// tile_size + 2 * border rows, announces each tile row as soon as its last row (border
// included) has arrived, and feeds every completed pair of rows, 2x2-averaged, to the next
// level (Backes et al., section 4; libvips dzsave's strip_arrived). Memory is about
// 2 x width x (tile + 2 border) x channels bytes whatever the height.

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include <tessera/format.h>
#include <tessera/result.h>

#include "tile_cutter.h"

namespace tessera::detail {

/// Receives tile rows. Called on the pyramid builder's thread; `rows` is valid only during
/// the call (cut what you need with cutTile before returning), unless cutsLater() is true.
class TileSink {
 public:
  virtual ~TileSink() = default;
  [[nodiscard]] virtual Result<void> tileRowReady(uint32_t level, uint32_t tile_row,
                                                  const LevelRows& rows) = 0;
  /// True when the sink cuts a tile row's tiles after tileRowReady returns (on other threads,
  /// through `rows`, which lives as long as the builder). The builder then calls awaitCut
  /// before it overwrites a row an announced tile row needs.
  virtual bool cutsLater() const { return false; }
  /// Blocks until every tile row of `level` up to `tile_row` (all announced) is cut: their band
  /// rows may be overwritten afterwards. Called on the builder's thread, only if cutsLater().
  virtual void awaitCut(uint32_t level, uint32_t tile_row) {
    (void)level;
    (void)tile_row;
  }
};

/// Owned by one thread.
class PyramidBuilder {
 public:
  /// `info` gives size, channels, tile size, border, level count and the sRGB flag. With
  /// `floor_average` levels are the unweighted floor average of downsampleRowPairFloor (the
  /// ptm codec's pyramid) and the sRGB flag must be off.
  PyramidBuilder(const ImageInfo& info, TileSink& sink, bool floor_average = false);
  /// Waits for the sink to cut every announced tile row (cutsLater), so no cut outlives the
  /// bands, whether the build finished or failed.
  ~PyramidBuilder();

  /// Adds `count` level-0 rows (tightly packed). Fails if the sink fails.
  [[nodiscard]] Result<void> addRows(const uint8_t* rows, uint32_t count);
  /// Where the next level-0 rows go, for a reader to decode straight into the band (no copy):
  /// room for 1 to `max_rows` rows, tightly packed, never more than the rows still to come,
  /// the band's contiguous slots, or the rows up to the next tile row's announcement (so no
  /// row a pending announcement or 2x2 pair needs is overwritten). Empty when all rows arrived.
  /// Fill a prefix of it, then commitRows with how many rows were written.
  [[nodiscard]] std::span<uint8_t> rowsToFill(uint32_t max_rows);
  /// Takes `count` rows written into the span of the last rowsToFill (count at most its rows),
  /// as addRows would. Fails if the sink fails.
  [[nodiscard]] Result<void> commitRows(uint32_t count);
  /// Rows received so far at level 0.
  uint32_t rowsReceived() const;
  /// Valid after all rows were added: checks every level emitted all its tile rows.
  [[nodiscard]] Result<void> finish();

 private:
  struct Level;
  Result<void> addRow(uint32_t level, const uint8_t* row);
  /// Takes the row already written at the level's next slot: averages it into the next level
  /// when it completes a pair, and announces the tile rows it completes.
  Result<void> rowArrived(uint32_t level);
  /// Before `count` rows from `first_row` are written into the level's ring: waits until the
  /// tile rows needing the rows they replace are cut (a sink that cuts later).
  void reuseSlots(uint32_t level, uint32_t first_row, uint32_t count);

  ImageInfo info_;
  TileSink& sink_;
  bool floor_average_;
  bool cuts_later_;  ///< the sink's cutsLater(), asked once
  std::vector<std::unique_ptr<Level>> levels_;
  uint32_t offered_rows_ = 0;  ///< rows the last rowsToFill offered, until committed
};

}  // namespace tessera::detail
