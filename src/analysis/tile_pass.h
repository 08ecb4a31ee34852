#pragma once
// The tile pass of a procedural build: every tile of every level queried, analysed, composited
// and encoded on a fixed set of worker threads, each with its own database connection (a
// connection is owned by one thread). Work units are allocated from one counter.

#include <atomic>
#include <chrono>
#include <functional>
#include <mutex>
#include <optional>
#include <vector>

#include <tessera/procedural.h>
#include <tessera/procedural_build.h>

#include "analysis/storage_choice.h"
#include "analysis/tile_analysis.h"
#include "mixed_writer.h"
#include "output/output_file.h"

namespace tessera::detail {

/// Everything the tile workers share. Each worker writes only its own tiles' slots.
struct BuildContext {
  const ProceduralBuildOptions* options = nullptr;
  ImageInfo info;
  std::shared_ptr<const BrushSet> set;
  AnalysisRules rules;
  DetailMap detail;
  uint32_t resource_layer = 0;  ///< resource id of the height layer (= brush count)
  const TempFile* spool = nullptr;
  std::atomic<uint64_t> spool_end{0};
  std::vector<uint64_t> level_first;  ///< flat index of each level's first tile
  std::vector<std::vector<MixedTile>> tiles;
  std::vector<StorageTile> storage;  ///< by flat index
  std::vector<double> estimated_ms, measured_ms;
  std::atomic<uint64_t> next{0}, done{0};
  std::atomic<uint64_t> queried{0}, covered{0}, small{0}, dropped{0}, query_ns{0};
  std::mutex error_mutex;  // guards first_error
  std::optional<Error> first_error;
  const std::atomic<bool>* cancel = nullptr;

  void recordError(Error error) {
    std::lock_guard lock(error_mutex);
    if (!first_error) first_error = std::move(error);
  }
  bool stopping() {
    std::lock_guard lock(error_mutex);
    return first_error.has_value() || (cancel && cancel->load());
  }
};

/// Runs the pass: fills `tiles`, `storage`, `estimated_ms`, `measured_ms` and the counters.
/// Fails with the first tile's error, or kCancelled.
[[nodiscard]] Result<void> runTilePass(
    BuildContext& context, const std::function<void(const ProceduralBuildProgress&)>& on_progress,
    std::chrono::steady_clock::time_point start);

}  // namespace tessera::detail
