// buildArchive: band readers -> streaming pyramid -> encoders on all cores -> spool -> layout.
#include <tessera/build.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <filesystem>
#include <map>
#include <mutex>
#include <optional>
#include <thread>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "archive_writer.h"
#include "band_reader.h"
#include "build_budget.h"
#include "build_internals.h"
#include "output/output_file.h"
#include "pyramid_builder.h"
#include "pyramid_source.h"
#include "tile_cutter.h"
#include "worker_pool.h"
#include "format/checksum.h"
#include "codecs/decode.h"
#include "codecs/encode.h"
#include "format/header.h"

namespace tessera {

using namespace detail;

namespace {

using Clock = std::chrono::steady_clock;

/// Recycled tile buffers for tiles padded on the building thread (an import's cropped or
/// missing tiles). Their count bounds those tiles in flight, and recycling avoids a fresh mmap
/// per tile.
class TileBufferPool {
 public:
  TileBufferPool(size_t count, size_t bytes) {
    for (size_t i = 0; i < count; ++i)
      free_.push_back(std::make_unique<std::vector<uint8_t>>(bytes));
  }
  std::unique_ptr<std::vector<uint8_t>> acquire() {
    std::unique_lock lock(mutex_);
    available_.wait(lock, [&] { return !free_.empty(); });
    auto buffer = std::move(free_.back());
    free_.pop_back();
    return buffer;
  }
  void release(std::unique_ptr<std::vector<uint8_t>> buffer) {
    {
      std::lock_guard lock(mutex_);
      free_.push_back(std::move(buffer));
    }
    available_.notify_one();
  }

 private:
  std::mutex mutex_;  // guards free_
  std::condition_variable available_;
  std::vector<std::unique_ptr<std::vector<uint8_t>>> free_;
};

/// A payload waiting in a worker's chunk for its spool offset.
struct PendingPayload {
  SpoolEntry* entry;
  uint64_t offset_in_chunk;
};

struct WorkerSpool {
  std::vector<uint8_t> chunk;
  std::vector<PendingPayload> pending;
};

/// State shared by the cutter (this thread) and the encoders.
struct EncodeContext {
  const TempFile* spool = nullptr;
  std::atomic<uint64_t> spool_end{0};
  EncodeOptions encode_options;
  Codec codec = Codec::kJpeg;
  SampleType sample_type = SampleType::kU8;  ///< of the image being encoded
  std::vector<WorkerSpool> worker_spools;    ///< indexed by WorkerState::index
  std::atomic<uint64_t> tiles_encoded{0}, tiles_uniform{0}, tiles_empty{0};
  uint64_t tiles_copied = 0;  ///< imported payloads taken as stored (the building thread's)
  std::mutex error_mutex;     // guards first_error
  std::optional<Error> first_error;

  void recordError(Error error) {
    std::lock_guard lock(error_mutex);
    if (!first_error) first_error = std::move(error);
  }
  std::optional<Error> error() {
    std::lock_guard lock(error_mutex);
    return first_error;
  }
};

Result<void> flushWorkerSpool(EncodeContext& context, WorkerSpool& spool) {
  if (spool.chunk.empty()) return {};
  uint64_t base = context.spool_end.fetch_add(spool.chunk.size());
  TESSERA_TRY(context.spool->pwrite(base, spool.chunk));
  for (const PendingPayload& pending : spool.pending)
    pending.entry->spool_offset = base + pending.offset_in_chunk;
  spool.chunk.clear();
  spool.pending.clear();
  return {};
}

void encodeJobOrThrow(EncodeContext& context, WorkerState& worker, SpoolEntry& entry,
                      const uint8_t* texels, uint32_t side, uint32_t channels,
                      const std::string& what, const ParentTexels* parent) {
  uint32_t colour = 0;
  // Wide samples have no uniform entries (docs/format.md, "Sample types"): every tile is coded.
  const TileClass tile_class = context.sample_type == SampleType::kU8
                                   ? classifyTile(texels, side, channels, &colour)
                                   : TileClass::kMixed;
  switch (tile_class) {
    case TileClass::kEmpty:
      entry.kind = TileKind::kEmpty;
      ++context.tiles_empty;
      return;
    case TileClass::kUniform:
      entry.kind = TileKind::kUniform;
      entry.uniform_rgba = colour;
      ++context.tiles_uniform;
      return;
    case TileClass::kMixed: break;
  }
  const size_t texel_bytes = size_t(channels) * sampleBytes(context.sample_type);
  ImageView view{texels, side, side, channels, side * texel_bytes, context.sample_type};
  auto payload =
      encodeTile(context.codec, view, context.encode_options, parent, &worker.codec_scratch);
  if (!payload) {
    context.recordError({payload.error().code, what + ": " + payload.error().message});
    return;
  }
  if (payload->size() > UINT32_MAX) {
    context.recordError({ErrorCode::kTooLarge, what + ": payload over 4 GiB"});
    return;
  }
  entry.kind = TileKind::kEncoded;
  entry.codec = context.codec;
  entry.length_bytes = uint32_t(payload->size());
  entry.checksum = checksum64(*payload);
  WorkerSpool& spool = context.worker_spools[worker.index];
  spool.pending.push_back({&entry, spool.chunk.size()});
  spool.chunk.insert(spool.chunk.end(), payload->begin(), payload->end());
  ++context.tiles_encoded;
  if (spool.chunk.size() >= kSpoolChunkBytes) {
    Result<void> flushed = flushWorkerSpool(context, spool);
    if (!flushed) context.recordError(flushed.error());
  }
}

// An exception (std::bad_alloc in a codec) must not leave the worker thread: it would end the
// process, and the job's tile buffer would never return to the pool. It fails the build.
void encodeJob(EncodeContext& context, WorkerState& worker, SpoolEntry& entry,
               const uint8_t* texels, uint32_t side, uint32_t channels, const std::string& what,
               const ParentTexels* parent = nullptr) {
  try {
    encodeJobOrThrow(context, worker, entry, texels, side, channels, what, parent);
  } catch (const std::bad_alloc&) {
    context.recordError({ErrorCode::kTooLarge, what + ": out of memory while encoding"});
  } catch (const std::exception& e) {
    context.recordError({ErrorCode::kInternal, what + ": " + e.what()});
  }
}

class EncodingSink final : public TileSink {
 public:
  EncodingSink(const ImageInfo& info, SpooledImage& spooled, EncodeContext& context,
               WorkerPool& pool, const std::string& source_name)
      : info_(info),
        spooled_(spooled),
        context_(context),
        pool_(pool),
        source_name_(source_name),
        uncut_(info.level_count),
        announced_(info.level_count, 0),
        cut_rows_(info.level_count, 0) {
    for (uint32_t l = 0; l < info.level_count; ++l) uncut_[l].assign(info.tilesY(l), 0);
  }

  Result<void> tileRowReady(uint32_t level, uint32_t tile_row, const LevelRows& rows) override {
    growEntries(level, tile_row);
    if (level + 1 == info_.level_count)
      statistics = info_.sample_type == SampleType::kU8 ? coarsestLevelStatistics(rows)
                                                        : wideLevelStatistics(rows);
    if (codecNeedsParent(context_.codec)) return holdRow(level, tile_row, rows);
    {
      std::lock_guard lock(cut_mutex_);
      uncut_[level][tile_row] = info_.tilesX(level);
      announced_[level] = tile_row + 1;
    }
    // Each encoder cuts its own tile out of the band (the pyramid keeps the rows until
    // awaitCut), so the building thread copies no tile.
    for (uint32_t x = 0; x < info_.tilesX(level); ++x) {
      SpoolEntry* entry = &spooled_.entries[level][size_t(tile_row) * info_.tilesX(level) + x];
      pool_.submit([this, &rows, entry, level, x, tile_row](WorkerState& worker) {
        encodeFromBand(worker, rows, *entry, level, x, tile_row);
      });
    }
    return {};
  }

  bool cutsLater() const override { return !codecNeedsParent(context_.codec); }

  void awaitCut(uint32_t level, uint32_t tile_row) override {
    std::unique_lock lock(cut_mutex_);
    tile_row_cut_.wait(lock, [&] { return cut_rows_[level] > tile_row; });
  }

  nlohmann::json statistics;

 private:
  // A level's entries are reserved whole and come into being a tile row at a time, as the rows
  // arrive: a reservation costs no resident memory, and within it a vector never moves, so
  // the encoders' entry pointers stay valid.
  void growEntries(uint32_t level, uint32_t tile_row) {
    std::vector<SpoolEntry>& entries = spooled_.entries[level];
    const size_t needed = size_t(tile_row + 1) * info_.tilesX(level);
    TESSERA_CHECK(needed <= entries.capacity()) << "tile row past the level's reservation";
    if (entries.size() < needed) entries.resize(needed);
  }

  // An encoder's job: cut, let the band's rows go, encode. Encoding JPEG straight from the band
  // (a strided view, no copy) was measured slower (1.5 against 1.2 user-s at 268 MP), likely
  // because a power-of-two level's row pitch is a multiple of 4 KiB and a tile's rows alias in
  // the cache; the packed copy is cheaper than that.
  void encodeFromBand(WorkerState& worker, const LevelRows& rows, SpoolEntry& entry, uint32_t level,
                      uint32_t x, uint32_t tile_row) {
    TESSERA_CHECK(worker.tile_texels.size() >= info_.storedTileBytes())
        << "worker tile buffer not sized";
    cutTile(rows, info_.tile_size_px, info_.border_px, x, tile_row, worker.tile_texels.data());
    tileCut(level, tile_row);
    encodeJob(context_, worker, entry, worker.tile_texels.data(), info_.storedTileSidePx(),
              info_.channels, fmt::format("{}: tile ({},{},{})", source_name_, level, x, tile_row));
  }

  // Called by an encoder once its tile is cut.
  void tileCut(uint32_t level, uint32_t tile_row) {
    {
      std::lock_guard lock(cut_mutex_);
      --uncut_[level][tile_row];
      uint32_t& cut = cut_rows_[level];
      while (cut < announced_[level] && uncut_[level][cut] == 0) ++cut;
    }
    tile_row_cut_.notify_all();
  }

  // Codecs that code a tile against its parent (ptm) need the parent's tile row, which the
  // streaming pyramid cuts after both of its child rows (or, without borders, between them).
  // So a row's raw tiles are held until its parent row exists, and a parent row until both
  // child rows are submitted: at most about three tile rows per level.
  struct HeldRow {
    std::vector<std::vector<uint8_t>> tiles;  ///< stored tiles, raw, x = 0..tilesX - 1
    bool submitted = false;                   ///< encode jobs queued for this row
    uint32_t children_waiting = 0;            ///< child rows not yet submitted against it
  };

  Result<void> holdRow(uint32_t level, uint32_t tile_row, const LevelRows& rows) {
    if (held_.empty()) held_.resize(info_.level_count);
    auto row = std::make_shared<HeldRow>();
    row->tiles.resize(info_.tilesX(level));
    for (uint32_t x = 0; x < info_.tilesX(level); ++x) {
      row->tiles[x].resize(info_.storedTileBytes());
      cutTile(rows, info_.tile_size_px, info_.border_px, x, tile_row, row->tiles[x].data());
    }
    const uint32_t first_child = 2 * tile_row;
    if (level > 0) row->children_waiting = std::min(2u, info_.tilesY(level - 1) - first_child);
    const uint32_t children = row->children_waiting;
    held_[level][tile_row] = row;

    if (level + 1 == info_.level_count) {
      submitRow(level, tile_row, row, nullptr);
    } else if (auto parent = held_[level + 1].find(tile_row / 2);
               parent != held_[level + 1].end()) {
      submitRow(level, tile_row, row, parent->second);
    }
    for (uint32_t child = first_child; child < first_child + children; ++child) {
      auto it = held_[level - 1].find(child);
      if (it != held_[level - 1].end() && !it->second->submitted)
        submitRow(level - 1, child, it->second, row);
    }
    return {};
  }

  // Queues the row's tiles; the jobs share ownership of the row and its parent row, which are
  // freed when the last job is done and the bookkeeping below has let go of them.
  // By value: releasing the rows below may drop the map's references while this runs.
  void submitRow(uint32_t level, uint32_t tile_row, std::shared_ptr<HeldRow> row,
                 std::shared_ptr<HeldRow> parent) {
    row->submitted = true;
    const uint32_t side = info_.storedTileSidePx();
    for (uint32_t x = 0; x < info_.tilesX(level); ++x) {
      SpoolEntry* entry = &spooled_.entries[level][size_t(tile_row) * info_.tilesX(level) + x];
      pool_.submit([this, row, parent, entry, side, level, x, tile_row](WorkerState& worker) {
        std::optional<ParentTexels> parent_texels;
        if (parent) {
          const std::vector<uint8_t>& texels = parent->tiles[x / 2];
          parent_texels = ParentTexels{
              {texels.data(), side, side, info_.channels, size_t(side) * info_.channels},
              x & 1,
              tile_row & 1,
              info_.tile_size_px,
              info_.border_px};
        }
        encodeJob(context_, worker, *entry, row->tiles[x].data(), side, info_.channels,
                  fmt::format("{}: tile ({},{},{})", source_name_, level, x, tile_row),
                  parent_texels ? &*parent_texels : nullptr);
      });
    }
    if (parent) --parent->children_waiting;
    release(level, tile_row);
    if (parent) release(level + 1, tile_row / 2);
  }

  void release(uint32_t level, uint32_t tile_row) {
    auto it = held_[level].find(tile_row);
    if (it != held_[level].end() && it->second->submitted && it->second->children_waiting == 0)
      held_[level].erase(it);
  }

  /// Per level, rows held for the parent-coded path, by tile row. Owned by the cutter thread.
  std::vector<std::map<uint32_t, std::shared_ptr<HeldRow>>> held_;

  const ImageInfo& info_;
  SpooledImage& spooled_;
  EncodeContext& context_;
  WorkerPool& pool_;
  const std::string& source_name_;

  // Which tile rows the encoders have cut, per level; guarded by cut_mutex_.
  std::mutex cut_mutex_;
  std::condition_variable tile_row_cut_;
  std::vector<std::vector<uint32_t>> uncut_;  ///< per level and tile row: tiles not yet cut
  std::vector<uint32_t> announced_;           ///< per level: tile rows announced
  std::vector<uint32_t> cut_rows_;            ///< per level: leading tile rows wholly cut
};

/// The build's sources, opened, with the images they become.
struct OpenedSources {
  std::vector<std::unique_ptr<BandReader>> readers;
  /// One per reader: the pyramid an input already is (docs/import.md), or null.
  std::vector<std::unique_ptr<PyramidSource>> pyramids;
  std::vector<ImageInfo> infos;    ///< one per reader, level_count set
  std::vector<std::string> names;  ///< one per reader: the input path or the row source's name
  uint64_t pixels_total = 0;       ///< level-0 pixels of every image
};

/// Wide samples need a codec that holds them and averaging in the sample type itself.
Result<void> checkSampleTypeOptions(const ImageInfo& info, const BuildOptions& options,
                                    const std::string& name) {
  // bc1 has no alpha: refused before any tile is encoded rather than at the first tile.
  if (options.codec == Codec::kBc1 && (info.channels == 2 || info.channels == 4))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: {} channels with alpha cannot be stored with --codec bc1 (it "
                            "keeps no alpha); use bc7",
                            name, info.channels));
  if (info.sample_type == SampleType::kU8) return {};
  if (!codecSupportsSampleType(options.codec, info.sample_type))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: {} samples cannot be stored with --codec {}; use zdelta, zstd, "
                            "lz4 or raw{}",
                            name, sampleTypeName(info.sample_type), codecName(options.codec),
                            info.sample_type == SampleType::kU16 ? " (or png)" : ""));
  if (options.srgb_downsample)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: --srgb averages 8-bit samples only, the image is {}", name,
                            sampleTypeName(info.sample_type)));
  return {};
}

/// Opens every source first (files, then the caller's row sources): bad inputs fail before any
/// output exists, and progress knows the total.
Result<OpenedSources> openSources(const BuildOptions& options) {
  OpenedSources sources;
  const size_t count = options.inputs.size() + options.row_sources.size();
  for (size_t i = 0; i < count; ++i) {
    const bool is_file = i < options.inputs.size();
    const std::string& name =
        is_file ? options.inputs[i] : options.row_sources[i - options.inputs.size()].name;
    std::unique_ptr<PyramidSource> pyramid;
    if (is_file) {
      TESSERA_ASSIGN_OR_RETURN(pyramid, openPyramidSource(name));
    }
    TESSERA_ASSIGN_OR_RETURN(
        std::unique_ptr<BandReader> reader,
        pyramid   ? pyramid->openLevel(0)
        : is_file ? openBandReader(name)
                  : openRowSourceReader(options.row_sources[i - options.inputs.size()]));
    const SourceInfo& source = reader->info();
    ImageInfo info;
    info.width_px = source.width_px;
    info.height_px = source.height_px;
    info.channels = source.channels;
    info.sample_type = source.sample_type;
    info.tile_size_px = options.tile_size_px;
    info.border_px = options.border_px;
    info.page_tiles_log2 = options.page_tiles_log2;
    info.default_codec = options.codec;
    info.srgb_downsample = options.srgb_downsample;
    info.name = i < options.image_names.size() ? options.image_names[i]
                : is_file                      ? displayName(name)
                                               : name;
    TESSERA_TRY(validateImageInfo(info, name));
    TESSERA_TRY(checkSampleTypeOptions(info, options, name));
    info.level_count = levelCountFor(info.width_px, info.height_px, info.tile_size_px);
    sources.pixels_total += uint64_t(info.width_px) * info.height_px;
    sources.readers.push_back(std::move(reader));
    sources.pyramids.push_back(std::move(pyramid));
    sources.infos.push_back(info);
    sources.names.push_back(name);
  }
  return sources;
}

/// A build's progress across its images, reported at most every 100 ms.
struct BuildProgressClock {
  const std::function<void(const BuildProgress&)>& on_progress;
  const Clock::time_point start;
  const uint64_t pixels_total;
  uint64_t pixels_done = 0;
  Clock::time_point last = Clock::now();

  void rowsRead(uint64_t pixels, const EncodeContext& context) {
    pixels_done += pixels;
    if (!on_progress || Clock::now() - last <= std::chrono::milliseconds(100)) return;
    last = Clock::now();
    on_progress({pixels_done, pixels_total,
                 context.tiles_encoded + context.tiles_uniform + context.tiles_empty,
                 std::chrono::duration<double>(last - start).count()});
  }
};

/// What the builder and the encoders share while the images stream through.
struct EncodeStage {
  EncodeContext& context;
  WorkerPool& pool;
  TileBufferPool& buffers;
  BuildProgressClock& progress;
  const std::atomic<bool>* cancel;
  bool cancelled() const { return cancel && cancel->load(std::memory_order_relaxed); }
};

/// Waits for the pool's jobs when it goes out of scope: queued jobs hold the sink and buffers
/// of the image being encoded, so no early return may outrun them.
struct PoolDrain {
  WorkerPool& pool;
  ~PoolDrain() { pool.waitIdle(); }
};

/// Feeds every row of `reader` (an image of `info`'s size) to `pyramid`, then finishes it.
Result<void> streamRows(const BuildOptions& options, const ImageInfo& info, BandReader& reader,
                        PyramidBuilder& pyramid, EncodeStage& stage, bool count_progress) {
  const uint32_t band_rows = bandRowsFor(info, reader.info());
  const size_t row_bytes = size_t(info.width_px) * info.texelBytes();
  // The reader decodes straight into the pyramid's level-0 band: no copy of the image's rows.
  for (uint32_t y = 0; y < info.height_px;) {
    if (stage.cancelled()) return fail(ErrorCode::kCancelled, options.output + ": build cancelled");
    if (auto error = stage.context.error()) return Unexpected(*error);
    std::span<uint8_t> slots = pyramid.rowsToFill(band_rows);
    TESSERA_CHECK(!slots.empty()) << "pyramid full at row " << y << " of " << info.height_px;
    const uint32_t rows = uint32_t(slots.size() / row_bytes);
    TESSERA_TRY(reader.readRows(rows, slots));
    TESSERA_TRY(pyramid.commitRows(rows));
    y += rows;
    if (count_progress) stage.progress.rowsRead(uint64_t(rows) * info.width_px, stage.context);
  }
  return pyramid.finish();
}

/// Streams image `index` band by band through the pyramid into the encoders and returns its
/// metadata; every tile is encoded into `spooled` when it returns.
Result<nlohmann::json> encodeImage(const BuildOptions& options, const std::string& source_name,
                                   const ImageInfo& info, BandReader& reader, SpooledImage& spooled,
                                   EncodeStage& stage) {
  spooled.info = info;
  spooled.entries.resize(info.level_count);
  for (uint32_t l = 0; l < info.level_count; ++l)
    spooled.entries[l].reserve(size_t(info.tilesX(l)) * info.tilesY(l));
  EncodingSink sink(info, spooled, stage.context, stage.pool, source_name);
  PyramidBuilder pyramid(info, sink, /*floor_average=*/options.codec == Codec::kPtm);
  stage.context.sample_type = info.sample_type;
  PoolDrain drain{stage.pool};
  TESSERA_TRY(streamRows(options, info, reader, pyramid, stage, /*count_progress=*/true));
  for (uint32_t l = 0; l < info.level_count; ++l)
    TESSERA_CHECK(spooled.entries[l].size() == size_t(info.tilesX(l)) * info.tilesY(l))
        << "level " << l << " has tile rows the pyramid never announced";
  stage.pool.waitIdle();  // queued jobs hold `sink`, which dies with this call
  return imageMetadata(info, source_name, reader.info(), sink.statistics);
}

/// Hands the rows of a pass over an imported level to the image's sink at their archive level,
/// dropping the levels the import copies.
class LevelShiftSink final : public TileSink {
 public:
  LevelShiftSink(TileSink& sink, uint32_t first_level, const std::vector<int>& copied_from)
      : sink_(sink), first_level_(first_level), copied_from_(copied_from) {}
  Result<void> tileRowReady(uint32_t level, uint32_t tile_row, const LevelRows& rows) override {
    const uint32_t archive_level = first_level_ + level;
    if (copied_from_[archive_level] >= 0) return {};
    return sink_.tileRowReady(archive_level, tile_row, rows);
  }
  bool cutsLater() const override { return sink_.cutsLater(); }
  void awaitCut(uint32_t level, uint32_t tile_row) override {
    const uint32_t archive_level = first_level_ + level;
    if (copied_from_[archive_level] < 0) sink_.awaitCut(archive_level, tile_row);
  }

 private:
  TileSink& sink_;
  const uint32_t first_level_;
  const std::vector<int>& copied_from_;
};

/// A tile the source stores cropped (a Deep Zoom edge tile) or not at all (a sparse TIFF
/// tile): padded to the stored tile by edge replication, as cutTile pads, and encoded.
Result<void> submitPaddedTile(const ImageInfo& info, uint32_t level, uint32_t x, uint32_t y,
                              SourceTile tile, SpoolEntry& entry, EncodeStage& stage,
                              std::string what) {
  const uint32_t side = info.storedTileSidePx();
  // Copied levels have no border: the stored tile is the tile.
  const uint32_t width =
      std::min(info.tile_size_px, info.levelWidthPx(level) - x * info.tile_size_px);
  const uint32_t height =
      std::min(info.tile_size_px, info.levelHeightPx(level) - y * info.tile_size_px);
  const uint32_t c = info.texelBytes();
  if (tile.width_px != width || tile.height_px != height ||
      tile.texels.size() != size_t(width) * height * c)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: the source's tile is {}x{} px, not {}x{}", what, tile.width_px,
                            tile.height_px, width, height));
  auto buffer = stage.buffers.acquire();
  for (uint32_t row = 0; row < side; ++row) {
    const uint8_t* src = tile.texels.data() + size_t(std::min(row, height - 1)) * width * c;
    uint8_t* dst = buffer->data() + size_t(row) * side * c;
    std::memcpy(dst, src, size_t(width) * c);
    for (uint32_t col = width; col < side; ++col)
      std::memcpy(dst + col * c, src + (width - 1) * c, c);
  }
  auto* raw = buffer.release();
  stage.pool.submit(
      [&stage, &info, raw, &entry, side, what = std::move(what)](WorkerState& worker) {
        std::unique_ptr<std::vector<uint8_t>> owned(raw);
        encodeJob(stage.context, worker, entry, owned->data(), side, info.channels, what);
        stage.buffers.release(std::move(owned));
      });
  return {};
}

/// Puts a payload taken as the source stores it into the spool as `entry`'s.
Result<void> spoolCopiedPayload(std::span<const uint8_t> payload, Codec codec, SpoolEntry& entry,
                                WorkerSpool& copy_spool, EncodeStage& stage) {
  entry.kind = TileKind::kEncoded;
  entry.codec = codec;
  entry.length_bytes = uint32_t(payload.size());
  entry.checksum = checksum64(payload);
  copy_spool.pending.push_back({&entry, copy_spool.chunk.size()});
  copy_spool.chunk.insert(copy_spool.chunk.end(), payload.begin(), payload.end());
  ++stage.context.tiles_copied;
  if (copy_spool.chunk.size() >= kSpoolChunkBytes)
    TESSERA_TRY(flushWorkerSpool(stage.context, copy_spool));
  return {};
}

/// Copies archive level `level` tile for tile from the source's level `source_level`: whole
/// JPEG and zstd payloads go to the spool as stored; other tiles are padded and encoded.
Result<void> copyLevel(const std::string& source_name, const ImageInfo& info, uint32_t level,
                       PyramidSource& source, uint32_t source_level, SpooledImage& spooled,
                       WorkerSpool& copy_spool, EncodeStage& stage) {
  std::vector<SpoolEntry>& entries = spooled.entries[level];
  entries.resize(size_t(info.tilesX(level)) * info.tilesY(level));
  for (uint32_t y = 0; y < info.tilesY(level); ++y) {
    if (stage.cancelled()) return fail(ErrorCode::kCancelled, source_name + ": build cancelled");
    if (auto error = stage.context.error()) return Unexpected(*error);
    for (uint32_t x = 0; x < info.tilesX(level); ++x) {
      std::string what = fmt::format("{}: tile ({},{},{})", source_name, level, x, y);
      TESSERA_ASSIGN_OR_RETURN(SourceTile tile, source.readTile(source_level, x, y));
      SpoolEntry& entry = entries[size_t(y) * info.tilesX(level) + x];
      if (!tile.jpeg.empty()) {
        TESSERA_TRY(checkJpegTile(tile.jpeg, info.storedTileSidePx(), info.channels, what));
        TESSERA_TRY(spoolCopiedPayload(tile.jpeg, Codec::kJpeg, entry, copy_spool, stage));
      } else if (!tile.zstd.empty()) {
        // The source checked the frame; checked again here because a wrong size would only
        // show when the tile is viewed.
        if (!isWholeZstdFrame(tile.zstd, info.storedTileBytes()))
          return fail(ErrorCode::kCorrupt,
                      fmt::format("{}: stored zstd tile is not one frame of {} bytes", what,
                                  info.storedTileBytes()));
        TESSERA_TRY(spoolCopiedPayload(tile.zstd, Codec::kZstd, entry, copy_spool, stage));
      } else {
        TESSERA_TRY(submitPaddedTile(info, level, x, y, std::move(tile), entry, stage, what));
      }
    }
    if (level == 0) {
      const uint32_t rows = std::min(info.tile_size_px, info.height_px - y * info.tile_size_px);
      stage.progress.rowsRead(uint64_t(rows) * info.width_px, stage.context);
    }
  }
  return {};
}

/// Imports an image that is already a pyramid (docs/import.md): the levels planImport copies
/// are copied, then each pass streams a decoded source level through the pyramid for the
/// levels computed from it. `base` reads the source's level 0.
Result<nlohmann::json> importImage(const BuildOptions& options, const std::string& source_name,
                                   const ImageInfo& info, PyramidSource& source, BandReader& base,
                                   SpooledImage& spooled, EncodeStage& stage) {
  spooled.info = info;
  spooled.entries.resize(info.level_count);
  for (uint32_t l = 0; l < info.level_count; ++l)
    spooled.entries[l].reserve(size_t(info.tilesX(l)) * info.tilesY(l));
  const ImportPlan plan = planImport(info, source.levels(), !codecNeedsParent(options.codec));
  EncodingSink sink(info, spooled, stage.context, stage.pool, source_name);
  stage.context.sample_type = info.sample_type;
  PoolDrain drain{stage.pool};
  WorkerSpool copy_spool;
  nlohmann::json copied = nlohmann::json::array();
  for (uint32_t l = 0; l < info.level_count; ++l) {
    if (plan.copied_from[l] < 0) continue;
    TESSERA_TRY(copyLevel(source_name, info, l, source, uint32_t(plan.copied_from[l]), spooled,
                          copy_spool, stage));
    copied.push_back(l);
  }
  TESSERA_TRY(flushWorkerSpool(stage.context, copy_spool));
  for (const ImportPlan::Pass& pass : plan.passes) {
    std::unique_ptr<BandReader> opened;
    if (pass.source_level != 0) {
      TESSERA_ASSIGN_OR_RETURN(opened, source.openLevel(pass.source_level));
    }
    BandReader& reader = opened ? *opened : base;
    ImageInfo pass_info = info;
    pass_info.width_px = info.levelWidthPx(pass.first_level);
    pass_info.height_px = info.levelHeightPx(pass.first_level);
    pass_info.level_count = pass.last_level - pass.first_level + 1;
    const SourceInfo& level_info = reader.info();
    if (level_info.width_px != pass_info.width_px || level_info.height_px != pass_info.height_px ||
        level_info.channels != info.channels || level_info.sample_type != info.sample_type)
      return fail(
          ErrorCode::kCorrupt,
          fmt::format("{}: pyramid level {} decodes as {}x{} px with {} channel(s) of {}, "
                      "not {}x{} with {} of {}",
                      source_name, pass.source_level, level_info.width_px, level_info.height_px,
                      level_info.channels, sampleTypeName(level_info.sample_type),
                      pass_info.width_px, pass_info.height_px, info.channels,
                      sampleTypeName(info.sample_type)));
    LevelShiftSink shifted(sink, pass.first_level, plan.copied_from);
    PyramidBuilder pyramid(pass_info, shifted, /*floor_average=*/options.codec == Codec::kPtm);
    const bool counts = pass.source_level == 0 && plan.copied_from[0] < 0;
    TESSERA_TRY(streamRows(options, pass_info, reader, pyramid, stage, counts));
  }
  stage.pool.waitIdle();  // queued jobs hold `sink`, which dies with this call
  if (auto error = stage.context.error()) return Unexpected(*error);
  nlohmann::json meta = imageMetadata(info, source_name, base.info(), sink.statistics);
  meta["import"] = {{"source_levels", source.levels().size()}, {"copied_levels", copied}};
  return meta;
}

/// Streams every image into the spool and returns their metadata entries, the worker spools
/// flushed.
Result<nlohmann::json> encodeImages(const BuildOptions& options, OpenedSources& sources,
                                    std::vector<SpooledImage>& spooled, EncodeContext& context,
                                    uint32_t threads, BuildProgressClock& progress,
                                    const std::atomic<bool>* cancel) {
  nlohmann::json image_metadata = nlohmann::json::array();
  TESSERA_ASSIGN_OR_RETURN(std::unique_ptr<WorkerPool> started,
                           WorkerPool::start(threads, 2 * threads));
  WorkerPool& pool = *started;
  size_t max_tile_bytes = 0;
  for (const ImageInfo& info : sources.infos)
    max_tile_bytes = std::max(max_tile_bytes, info.storedTileBytes());
  TileBufferPool buffers(3 * threads + 2, max_tile_bytes);
  for (uint32_t i = 0; i < pool.threadCount(); ++i)
    pool.state(i).tile_texels.resize(max_tile_bytes);
  EncodeStage stage{context, pool, buffers, progress, cancel};
  for (uint32_t i = 0; i < sources.infos.size(); ++i) {
    TESSERA_ASSIGN_OR_RETURN(
        nlohmann::json meta,
        sources.pyramids[i]
            ? importImage(options, sources.names[i], sources.infos[i], *sources.pyramids[i],
                          *sources.readers[i], spooled[i], stage)
            : encodeImage(options, sources.names[i], sources.infos[i], *sources.readers[i],
                          spooled[i], stage));
    image_metadata.push_back(std::move(meta));
  }
  pool.waitIdle();
  for (WorkerSpool& worker_spool : context.worker_spools)
    if (Result<void> flushed = flushWorkerSpool(context, worker_spool); !flushed)
      context.recordError(flushed.error());
  if (auto error = context.error()) return Unexpected(*error);
  return image_metadata;
}

/// What the build was checked to need before it started.
struct BuildBudget {
  MemoryEstimate memory;
  uint64_t memory_limit_bytes = 0;
  std::string spool_dir;  ///< where the spool goes: --spool-dir or the output's directory
};

/// The memory the sources' claimed sizes need, against the limit: before any row or tile is
/// allocated.
Result<BuildBudget> checkBudget(const BuildOptions& options, const OpenedSources& sources,
                                uint32_t threads) {
  BuildBudget budget;
  std::vector<const SourceInfo*> source_infos;
  for (const auto& reader : sources.readers) source_infos.push_back(&reader->info());
  budget.memory = estimateBuildMemory(sources.infos, source_infos, options.codec, threads);
  budget.memory_limit_bytes =
      options.memory_limit_bytes ? options.memory_limit_bytes : defaultBuildMemoryLimitBytes();
  const std::string origin = options.memory_limit_bytes
                                 ? "--memory-limit"
                                 : fmt::format("the default: half of the {} this machine has",
                                               formatByteCount(usableMemoryBytes()));
  TESSERA_TRY(checkMemoryBudget(budget.memory, budget.memory_limit_bytes, origin, sources.infos,
                                sources.names));
  budget.spool_dir = options.spool_dir.empty() ? directoryOf(options.output) : options.spool_dir;
  return budget;
}

}  // namespace

Result<BuildReport> buildArchive(const BuildOptions& options,
                                 const std::function<void(const BuildProgress&)>& on_progress,
                                 const std::atomic<bool>* cancel) {
  const auto start = Clock::now();
  TESSERA_TRY(validateBuildOptions(options));
  // An output that cannot be replaced fails before the inputs are read.
  TESSERA_TRY(checkOutputPath(options.output));
  TESSERA_ASSIGN_OR_RETURN(OpenedSources sources, openSources(options));
  const uint32_t threads =
      options.threads ? options.threads : std::max(1u, std::thread::hardware_concurrency());
  TESSERA_ASSIGN_OR_RETURN(const BuildBudget budget, checkBudget(options, sources, threads));
  TESSERA_ASSIGN_OR_RETURN(TempFile out, TempFile::create(options.output));
  TESSERA_ASSIGN_OR_RETURN(TempFile spool,
                           TempFile::createScratch(budget.spool_dir, options.output + ": spool"));
  // The files exist but are still invisible: a build that cannot fit leaves nothing behind.
  TESSERA_TRY(checkFreeSpace(options.output, directoryOf(options.output), budget.spool_dir,
                             estimateArchiveBytes(sources.infos, options.codec, options.quality)));

  EncodeContext context;
  context.spool = &spool;
  context.codec = options.codec;
  context.encode_options.quality = options.quality;
  context.encode_options.effort = options.effort;
  context.encode_options.chroma_subsampling = options.chroma_subsampling;
  context.worker_spools.resize(threads);

  std::vector<SpooledImage> spooled(sources.infos.size());
  BuildProgressClock progress{on_progress, start, sources.pixels_total};
  TESSERA_ASSIGN_OR_RETURN(
      nlohmann::json image_metadata,
      encodeImages(options, sources, spooled, context, threads, progress, cancel));
  auto cancelled = [&] { return cancel && cancel->load(std::memory_order_relaxed); };
  if (cancelled()) return fail(ErrorCode::kCancelled, options.output + ": build cancelled");

  TESSERA_ASSIGN_OR_RETURN(WrittenArchive written,
                           writeArchive(spool, context.spool_end.load(), spooled, options.order,
                                        archiveMetadata(options, std::move(image_metadata)), out));
  if (cancelled()) return fail(ErrorCode::kCancelled, options.output + ": build cancelled");
  TESSERA_TRY(out.commit());

  BuildReport report;
  report.output_bytes = written.file_bytes;
  report.payload_bytes = written.payload_bytes;
  report.tiles_encoded = context.tiles_encoded;
  report.tiles_copied = context.tiles_copied;
  report.tiles_uniform = context.tiles_uniform;
  report.tiles_empty = context.tiles_empty;
  report.elapsed_s = std::chrono::duration<double>(Clock::now() - start).count();
  report.megapixels_per_s = sources.pixels_total / 1e6 / std::max(report.elapsed_s, 1e-9);
  report.images = sources.infos;
  report.memory_estimate_bytes = budget.memory.totalBytes();
  report.memory_limit_bytes = budget.memory_limit_bytes;
  if (on_progress)
    on_progress(
        {sources.pixels_total, sources.pixels_total, report.tiles_encoded, report.elapsed_s});
  return report;
}

}  // namespace tessera
