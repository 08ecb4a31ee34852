#include "tile_pass.h"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <mutex>
#include <optional>
#include <thread>

#include <fmt/format.h>

#include <tessera/brushes.h>

#include "analysis/tile_analysis.h"
#include "codecs/encode.h"
#include "format/checksum.h"
#include "format/directory.h"
#include "format/procedural.h"

namespace tessera::detail {

namespace {

using Clock = std::chrono::steady_clock;

double millisecondsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

Result<uint64_t> spoolBytes(BuildContext& context, std::span<const uint8_t> bytes) {
  const uint64_t offset = context.spool_end.fetch_add(bytes.size());
  TESSERA_TRY(context.spool->pwrite(offset, bytes));
  return offset;
}

// Empty: every byte zero (nothing drawn). Uniform: every texel equals the first.
TileKind classify(const Image& texels, uint32_t* colour) {
  const uint8_t* p = texels.texels.data();
  const size_t count = texels.texels.size() / 4;
  for (size_t i = 1; i < count; ++i)
    if (std::memcmp(p, p + i * 4, 4) != 0) return TileKind::kEncoded;
  std::memcpy(colour, p, 4);
  return *colour == 0 ? TileKind::kEmpty : TileKind::kUniform;
}

BoxPx tileArea(const ImageInfo& info, uint32_t level, uint32_t x, uint32_t y) {
  const double scale = std::ldexp(1.0, int(level)), t = info.tile_size_px;
  return {x * t * scale, y * t * scale, (x + 1) * t * scale - 1e-9, (y + 1) * t * scale - 1e-9};
}

struct WorkerState {
  std::unique_ptr<BrushDatabase> database;
  std::vector<BrushInstance> candidates;
  Image texels;
  CodecScratch scratch;
};

// One tile: query, analyse, composite, encode the baked form and spool the page.
Result<void> processTile(BuildContext& context, WorkerState& worker, uint64_t flat) {
  const uint32_t level =
      uint32_t(std::upper_bound(context.level_first.begin(), context.level_first.end(), flat) -
               context.level_first.begin() - 1);
  const uint64_t in_level = flat - context.level_first[level];
  const uint32_t x = uint32_t(in_level % context.info.tilesX(level));
  const uint32_t y = uint32_t(in_level / context.info.tilesX(level));
  MixedTile& tile = context.tiles[level][in_level];
  StorageTile& storage = context.storage[flat];
  if (context.detail.dropsTile(tileArea(context.info, level, x, y), level)) {
    ++context.dropped;
    return {};
  }
  const TileGeometry geometry{level,
                              x,
                              y,
                              context.info.tile_size_px,
                              context.info.border_px,
                              context.info.width_px,
                              context.info.height_px};
  const std::string what = fmt::format("{}: tile ({},{},{})", context.options->output, level, x, y);
  worker.candidates.clear();
  const auto query_start = Clock::now();
  TESSERA_TRY(worker.database->query(tileQueryBox(geometry), worker.candidates));
  context.query_ns += uint64_t(millisecondsSince(query_start) * 1e6);
  context.queried += worker.candidates.size();
  Result<TileAnalysis> analysed =
      analyseTile(*context.set, geometry, worker.candidates, context.rules);
  if (!analysed) return fail(analysed.error().code, what + ": " + analysed.error().message);
  const TileAnalysis& analysis = *analysed;
  context.covered += analysis.covered;
  context.small += analysis.small;
  const auto composite_start = Clock::now();
  TESSERA_TRY(compositeTile(*context.set, geometry, analysis.kept, worker.texels, analysis.clips));
  context.measured_ms[flat] = millisecondsSince(composite_start);
  context.estimated_ms[flat] = analysis.estimated_ms;

  tile.baked_kind = classify(worker.texels, &tile.uniform_rgba);
  if (tile.baked_kind == TileKind::kEncoded) {
    EncodeOptions encode;
    encode.quality = context.options->quality;
    encode.effort = context.options->effort;
    Result<std::vector<uint8_t>> payload = encodeTile(
        context.info.default_codec, worker.texels.view(), encode, nullptr, &worker.scratch);
    if (!payload) return fail(payload.error().code, what + ": " + payload.error().message);
    TESSERA_ASSIGN_OR_RETURN(tile.payload_offset, spoolBytes(context, *payload));
    tile.payload_length = uint32_t(payload->size());
    tile.payload_checksum = checksum64(*payload);
    storage.baked_bytes = payload->size();
  }
  const uint64_t page_bytes = instancePageBytes(analysis.kept.size());
  if (tile.baked_kind == TileKind::kEncoded && !analysis.kept.empty() &&
      page_bytes <= maxPayloadBytes(context.info)) {
    const std::vector<uint8_t> page = encodeInstancePage(analysis.kept, analysis.clips);
    TESSERA_ASSIGN_OR_RETURN(tile.page_offset, spoolBytes(context, page));
    tile.page_length = uint32_t(page.size());
    tile.has_page = true;
    storage.procedural_bytes = page.size();
    storage.eligible = analysis.within_budget;
    bool masked = false;
    for (const BrushInstance& instance : analysis.kept) {
      storage.resources.push_back(instance.brush);
      masked |= context.set->brushes()[instance.brush].mask != MaskSource::kNone;
    }
    if (masked) storage.resources.push_back(context.resource_layer);
    std::sort(storage.resources.begin(), storage.resources.end());
    storage.resources.erase(std::unique(storage.resources.begin(), storage.resources.end()),
                            storage.resources.end());
  }
  return {};
}

void runWorker(BuildContext& context) {
  WorkerState worker;
  auto database = openBrushDatabase(context.options->database, false);
  if (!database) return context.recordError(database.error());
  worker.database = std::move(*database);
  const uint64_t total = context.storage.size();
  while (!context.stopping()) {
    const uint64_t flat = context.next++;
    if (flat >= total) break;
    Result<void> processed = processTile(context, worker, flat);
    if (!processed) return context.recordError(processed.error());
    ++context.done;
  }
}

}  // namespace

Result<void> runTilePass(BuildContext& context,
                         const std::function<void(const ProceduralBuildProgress&)>& on_progress,
                         Clock::time_point start) {
  uint32_t threads = context.options->threads ? context.options->threads
                                              : std::max(1u, std::thread::hardware_concurrency());
  std::vector<std::thread> workers;
  for (uint32_t i = 0; i < threads; ++i) workers.emplace_back([&context] { runWorker(context); });
  // This thread only reports progress: the workers allocate tiles among themselves.
  while (context.done.load() < context.storage.size() && !context.stopping()) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    if (on_progress)
      on_progress({context.done.load(), context.storage.size(), millisecondsSince(start) / 1000});
  }
  for (std::thread& worker : workers) worker.join();
  if (context.first_error) return Unexpected(*context.first_error);
  if (context.cancel && context.cancel->load())
    return fail(ErrorCode::kCancelled, context.options->output + ": build cancelled");
  return {};
}

}  // namespace tessera::detail
