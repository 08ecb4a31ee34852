// mergeArchiveParts: N part archives -> the archive of a single build (docs/builder.md,
// "Split and merge"). Payloads below level M are copied unchanged, a stretch stored together
// in a part at a time, in the output's clustering order; levels M and up are computed from the
// parts' exact level-M rows.
#include <tessera/split_build.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <utility>

#include <fmt/format.h>

#include "archive_writer.h"
#include "build_internals.h"
#include "codecs/encode.h"
#include "format/checksum.h"
#include "format/metadata.h"
#include "output/file_appender.h"
#include "output/output_file.h"
#include "part_build.h"
#include "pyramid_builder.h"
#include "worker_pool.h"

namespace tessera {

using namespace detail;

namespace {

struct OpenedPart {
  std::string path;
  std::shared_ptr<Archive> archive;
  nlohmann::json meta;  ///< its "split_part" metadata, checked by checkPartFields
  uint32_t index = 0;   ///< 1..count once openParts accepts it
  uint32_t count = 0;   ///< 1..kMaxBuildParts
  uint32_t merge_level = 0;
  uint32_t first_row = 0, end_row = 0;  ///< its level-0 rows, "rows"
};

/// The first place two JSON values differ, as a JSON pointer ("/build/quality").
std::string firstDifference(const nlohmann::json& a, const nlohmann::json& b) {
  const nlohmann::json patch = nlohmann::json::diff(a, b);
  return patch.empty() ? std::string() : patch[0]["path"].get<std::string>();
}

Result<void> metadataError(const OpenedPart& part, std::string_view field, const char* problem) {
  return fail(ErrorCode::kInvalidArgument,
              fmt::format("{}: metadata \"split_part.{}\" {}", part.path, field, problem));
}

/// Takes the numbers the merge relies on from `part.meta` and checks the types of the build
/// settings it uses: a damaged or hand-made part is an error naming the file and the field,
/// never a JSON exception.
Result<void> checkPartFields(OpenedPart& part) {
  const nlohmann::json& meta = part.meta;  // holds the keys openPart requires
  constexpr uint64_t kMax32 = UINT32_MAX;
  auto number = [&](const char* key, uint64_t max, uint32_t& out) -> Result<void> {
    TESSERA_ASSIGN_OR_RETURN(
        const uint64_t value,
        metadataUnsigned(meta[key], part.path, fmt::format("split_part.{}", key), max));
    out = uint32_t(value);
    return {};
  };
  TESSERA_TRY(number("index", kMax32, part.index));
  TESSERA_TRY(number("count", kMaxBuildParts, part.count));
  TESSERA_TRY(number("merge_level", kMax32, part.merge_level));
  const nlohmann::json& rows = meta["rows"];
  if (!rows.is_array() || rows.size() != 2)
    return metadataError(part, "rows", "is not a pair of row numbers");
  TESSERA_ASSIGN_OR_RETURN(part.first_row,
                           metadataUnsigned(rows[0], part.path, "split_part.rows[0]", kMax32));
  TESSERA_ASSIGN_OR_RETURN(part.end_row,
                           metadataUnsigned(rows[1], part.path, "split_part.rows[1]", kMax32));
  const nlohmann::json& archive_metadata = meta["archive_metadata"];
  if (!archive_metadata.is_object())
    return metadataError(part, "archive_metadata", "is not an object");
  const auto images = archive_metadata.find("images");
  if (images != archive_metadata.end() &&
      (!images->is_array() || (!images->empty() && !(*images)[0].is_object())))
    return metadataError(part, "archive_metadata.images", "is not an array of objects");
  const auto build = archive_metadata.find("build");
  if (build == archive_metadata.end() || !build->is_object())
    return metadataError(part, "archive_metadata.build", "is not an object");
  Codec codec = Codec::kRaw;
  const auto codec_name = build->find("codec");
  if (codec_name == build->end() || !codec_name->is_string() ||
      !parseCodecName(codec_name->get<std::string>(), &codec))
    return metadataError(part, "archive_metadata.build.codec", "is not a codec's name");
  const auto order = build->find("order");
  if (order == build->end() || !order->is_string())
    return metadataError(part, "archive_metadata.build.order", "is not a tile order's name");
  for (const char* key : {"quality", "effort"}) {
    const auto value = build->find(key);
    const std::string field = fmt::format("archive_metadata.build.{}", key);
    if (value == build->end()) return metadataError(part, field, "is missing");
    TESSERA_TRY(metadataInt(*value, part.path, "split_part." + field));
  }
  return {};
}

Result<OpenedPart> openPart(const std::string& path) {
  OpenedPart part;
  part.path = path;
  TESSERA_ASSIGN_OR_RETURN(part.archive, Archive::openFile(path));
  const nlohmann::json metadata = nlohmann::json::parse(part.archive->metadataJson(), nullptr,
                                                        /*allow_exceptions=*/false);
  if (!metadata.is_object() || !metadata.contains("split_part") ||
      !metadata["split_part"].is_object())
    return fail(ErrorCode::kInvalidArgument,
                path + ": not a part of a split build (no \"split_part\" in its metadata)");
  part.meta = metadata["split_part"];
  for (const char* key : {"index", "count", "merge_level", "rows", "input", "archive_metadata"})
    if (!part.meta.contains(key))
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}: split_part metadata lacks \"{}\"", path, key));
  // Refused like every part the merge cannot take (docs/builder.md: exit code 2).
  if (Result<void> checked = checkPartFields(part); !checked)
    return fail(ErrorCode::kInvalidArgument, checked.error().message);
  return part;
}

/// Every part of one build, exactly once, ordered by index.
Result<std::vector<OpenedPart>> openParts(const std::vector<std::string>& paths) {
  if (paths.empty()) return fail(ErrorCode::kInvalidArgument, "merge: no parts given");
  std::vector<OpenedPart> opened;
  for (const std::string& path : paths) {
    TESSERA_ASSIGN_OR_RETURN(OpenedPart part, openPart(path));
    opened.push_back(std::move(part));
  }
  const OpenedPart& first = opened[0];
  const uint32_t count = first.count;
  std::vector<const OpenedPart*> by_index(count, nullptr);
  // find, not a const operator[]: that is undefined for a key the object lacks.
  auto entry = [](const nlohmann::json& meta, const char* key) {
    const auto found = meta.find(key);
    return found == meta.end() ? nlohmann::json() : *found;
  };
  for (const OpenedPart& part : opened) {
    for (const char* key : {"count", "input", "archive_metadata", "page_tiles_log2"}) {
      const nlohmann::json mine = entry(part.meta, key), firsts = entry(first.meta, key);
      if (mine == firsts) continue;
      const std::string where = firstDifference(firsts, mine);
      const nlohmann::json::json_pointer pointer(where);
      auto at = [&](const nlohmann::json& value) {
        return value.contains(pointer) ? value.at(pointer).dump().substr(0, 200) : "none";
      };
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}: not a part of the same build as {}: its {}{} is {}, not {}",
                              part.path, first.path, key, where, at(mine), at(firsts)));
    }
    const uint32_t index = part.index;
    if (index < 1 || index > count)
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}: part index {} outside 1..{}", part.path, index, count));
    if (by_index[index - 1])
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{} and {} are both part {}/{}", by_index[index - 1]->path, part.path,
                              index, count));
    by_index[index - 1] = &part;
  }
  std::vector<uint32_t> missing;
  for (uint32_t i = 0; i < count; ++i)
    if (!by_index[i]) missing.push_back(i + 1);
  if (!missing.empty())
    return fail(
        ErrorCode::kInvalidArgument,
        fmt::format("merge: {} of {} parts missing (parts {}); given {} file(s) from the "
                    "build of {}",
                    missing.size(), count, fmt::join(missing, ", "), paths.size(), first.path));
  std::vector<OpenedPart> ordered;
  for (const OpenedPart* part : by_index) ordered.push_back(*part);
  return ordered;
}

/// Encodes the coarse levels' tiles as the pyramid announces them, like the builder's
/// encoders: cut and classified on this thread, encoded by `pool` while this thread decodes
/// and averages the next rows (the merge's only computing, and all of it before the copy).
class CoarseSink final : public TileSink {
 public:
  CoarseSink(const ImageInfo& level_info, uint32_t merge_level, SpooledImage& out,
             const nlohmann::json& build, WorkerPool& pool)
      : info_(level_info), merge_level_(merge_level), out_(out), pool_(pool) {
    parseCodecName(build["codec"].get<std::string>(), &codec_);
    options_.quality = build["quality"].get<int>();
    options_.effort = build["effort"].get<int>();
    const auto chroma = build.find("chroma_subsampling");
    options_.chroma_subsampling = chroma != build.end() && *chroma == "4:2:0";
  }

  Result<void> tileRowReady(uint32_t level, uint32_t tile_row, const LevelRows& rows) override {
    if (level + 1 == info_.level_count) statistics = coarsestLevelStatistics(rows);
    const uint32_t side = info_.storedTileSidePx();
    for (uint32_t x = 0; x < info_.tilesX(level); ++x) {
      std::vector<uint8_t> tile(info_.storedTileBytes());
      cutTile(rows, info_.tile_size_px, info_.border_px, x, tile_row, tile.data());
      SpoolEntry& entry =
          out_.entries[merge_level_ + level][size_t(tile_row) * info_.tilesX(level) + x];
      uint32_t colour = 0;
      const TileClass kind = classifyTile(tile.data(), side, info_.channels, &colour);
      if (kind != TileClass::kMixed) {
        entry.kind = kind == TileClass::kEmpty ? TileKind::kEmpty : TileKind::kUniform;
        entry.uniform_rgba = kind == TileClass::kEmpty ? 0 : colour;
        continue;
      }
      entry.spool_offset = payloads.size();
      std::vector<uint8_t>& payload = payloads.emplace_back();  // a deque: stays in place
      pool_.submit([this, tile = std::move(tile), side, &entry, &payload](WorkerState& state) {
        ImageView view{tile.data(), side, side, info_.channels, size_t(side) * info_.channels};
        Result<std::vector<uint8_t>> encoded =
            encodeTile(codec_, view, options_, nullptr, &state.codec_scratch);
        if (!encoded) {
          std::lock_guard<std::mutex> lock(error_mutex_);
          if (!error_) error_ = std::move(encoded).error();
          return;
        }
        payload = std::move(*encoded);
        entry.kind = TileKind::kEncoded;
        entry.codec = codec_;
        entry.length_bytes = uint32_t(payload.size());
        entry.checksum = checksum64(payload);
      });
    }
    return {};
  }

  /// The first encoding failure; valid after the pool's waitIdle().
  Result<void> error() {
    std::lock_guard<std::mutex> lock(error_mutex_);
    if (error_) return Unexpected(*error_);
    return {};
  }

  nlohmann::json statistics;
  /// By SpoolEntry::spool_offset; each filled by its encoding job.
  std::deque<std::vector<uint8_t>> payloads;

 private:
  const ImageInfo& info_;
  uint32_t merge_level_;
  SpooledImage& out_;
  WorkerPool& pool_;
  Codec codec_ = Codec::kJpeg;
  EncodeOptions options_;
  std::mutex error_mutex_;  // guards error_
  std::optional<Error> error_;
};

/// Streams the parts' exact level-M rows, part by part and tile row by tile row, through the
/// pyramid of levels M and up.
Result<void> computeCoarseLevels(const std::vector<OpenedPart>& parts, const ImageInfo& info,
                                 uint32_t merge_level, PyramidBuilder& pyramid) {
  const uint32_t width = info.levelWidthPx(merge_level);
  const size_t row_bytes = size_t(width) * info.channels;
  std::vector<uint8_t> band;
  for (const OpenedPart& part : parts) {
    if (part.archive->images().size() < 2) continue;
    const ImageInfo& rows_info = part.archive->images()[1];
    if (rows_info.width_px != width || rows_info.channels != info.channels)
      return fail(ErrorCode::kInvalidArgument,
                  part.path + ": its level rows do not match the image's geometry");
    const uint32_t t = rows_info.tile_size_px;
    for (uint32_t ty = 0; ty < rows_info.tilesY(0); ++ty) {
      const uint32_t rows = std::min(t, rows_info.height_px - ty * t);
      band.resize(row_bytes * rows);
      for (uint32_t tx = 0; tx < rows_info.tilesX(0); ++tx) {
        TESSERA_ASSIGN_OR_RETURN(Image tile, part.archive->readTile({1, 0, tx, ty}));
        const uint32_t columns = std::min(t, width - tx * t);
        for (uint32_t y = 0; y < rows; ++y)
          std::memcpy(band.data() + y * row_bytes + size_t(tx) * t * info.channels,
                      tile.texels.data() + size_t(y) * tile.strideBytes(),
                      size_t(columns) * info.channels);
      }
      if (pyramid.rowsReceived() + rows > info.levelHeightPx(merge_level))
        return fail(ErrorCode::kInvalidArgument,
                    part.path + ": the parts hold more level rows than the image has");
      TESSERA_TRY(pyramid.addRows(band.data(), rows));
    }
  }
  if (pyramid.rowsReceived() != info.levelHeightPx(merge_level))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("merge: the parts hold {} of the {} rows of level {}",
                            pyramid.rowsReceived(), info.levelHeightPx(merge_level), merge_level));
  return pyramid.finish();
}

/// The output's directory below level M, from the parts (spool_offset: the payload's offset
/// in its part); `owner[level][tile_row]` is the part holding each tile row.
Result<void> copyPartEntries(const std::vector<OpenedPart>& parts, const PartPlan& plan,
                             SpooledImage& out, std::vector<std::vector<uint32_t>>& owner) {
  const ImageInfo& info = out.info;
  owner.resize(plan.merge_level);
  for (uint32_t l = 0; l < plan.merge_level; ++l) owner[l].resize(info.tilesY(l));
  for (uint32_t p = 0; p < parts.size(); ++p) {
    if (parts[p].first_row != plan.firstRow(p) || parts[p].end_row != plan.firstRow(p + 1))
      return fail(ErrorCode::kInvalidArgument,
                  parts[p].path + ": its rows are not those the split assigns to its index");
    for (uint32_t l = 0; l < plan.merge_level; ++l) {
      for (uint32_t y = tileRowAt(info, l, plan.firstRow(p));
           y < tileRowAt(info, l, plan.firstRow(p + 1)); ++y) {
        owner[l][y] = p;
        for (uint32_t x = 0; x < info.tilesX(l); ++x) {
          TESSERA_ASSIGN_OR_RETURN(TileEntry entry, parts[p].archive->tileEntry({0, l, x, y}));
          out.entries[l][size_t(y) * info.tilesX(l) + x] = spoolEntryOf(entry);
        }
      }
    }
  }
  return {};
}

/// The buffers the stretches of the parts are read into, reused: the merging thread reads and
/// checks a stretch in one while the appender's writer thread writes the previous from another
/// and gives it back once written. Never more than kBuffers of kPayloadRunBytes, however large
/// the merge, and none allocated per stretch. Shared with the release callbacks the writer
/// runs, so it outlives them.
class StretchBuffers {
 public:
  /// One being filled, one being written: the appender hands its writer a block only once
  /// the previous is written and given back, so a third would never be taken.
  static constexpr size_t kBuffers = 2;

  /// A free buffer (allocated on first use), waiting for the writer to give one back when
  /// all are out.
  uint8_t* take() {
    std::unique_lock<std::mutex> lock(mutex_);
    given_back_.wait(lock, [&] { return !free_.empty() || owned_.size() < kBuffers; });
    if (free_.empty()) {
      owned_.push_back(std::make_unique_for_overwrite<uint8_t[]>(kPayloadRunBytes));
      return owned_.back().get();
    }
    uint8_t* buffer = free_.back();
    free_.pop_back();
    return buffer;
  }

  void giveBack(uint8_t* buffer) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      free_.push_back(buffer);
    }
    given_back_.notify_one();
  }

 private:
  std::mutex mutex_;  // guards the fields below
  std::condition_variable given_back_;
  std::vector<std::unique_ptr<uint8_t[]>> owned_;
  std::vector<uint8_t*> free_;
};

/// Places the payloads of the writer's runs: the coarse levels' from memory, the others from
/// the parts. A run's payloads from one part lie back to back there (the part is written in
/// the output's order), so each such stretch is one read of the part's byte source into a
/// buffer of a small pool, its checksums verified there, and handed to the appender's writer
/// thread, which writes it to the output while the next stretch is read and checked. Reads,
/// not a mapping: a part cut short by another process (parts live on shared file systems) is
/// then a short read, which the source reports naming the part, where reading a mapping past
/// the file's end kills the process.
class PayloadCopier {
 public:
  PayloadCopier(const std::vector<OpenedPart>& parts, uint32_t merge_level,
                const std::vector<std::vector<uint32_t>>& owner,
                const std::deque<std::vector<uint8_t>>& coarse_payloads)
      : parts_(parts),
        merge_level_(merge_level),
        owner_(owner),
        coarse_payloads_(coarse_payloads) {}

  /// Appends `run`'s payloads, counting what came from the parts in `report`.
  Result<void> append(std::span<const RunTile> run, FileAppender& appender, MergeReport& report) {
    auto part_of = [&](const RunTile& tile) -> int64_t {
      if (tile.tile.level >= merge_level_) return -1;  // computed by the merge
      return owner_[tile.tile.level][tile.tile.y];
    };
    auto same_part = [&](const RunTile& a, const RunTile& b) {
      return part_of(a) >= 0 && part_of(a) == part_of(b);
    };
    auto place = [&](size_t first, size_t end, uint64_t offset, size_t,
                     size_t length) -> Result<void> {
      const int64_t owner_part = part_of(run[first]);
      if (owner_part < 0) {
        TESSERA_TRY(appender.append(coarse_payloads_[run[first].entry->spool_offset]));
        return {};
      }
      TESSERA_TRY(copyStretch(size_t(owner_part), run.subspan(first, end - first), offset, length,
                              appender));
      report.payload_bytes_copied += length;
      report.tiles_copied += end - first;
      ++report.part_reads;
      return {};
    };
    return forEachStoredRange(run, place, same_part);
  }

 private:
  /// `tiles`, stored back to back from `offset` in part `p`, onto the output.
  Result<void> copyStretch(size_t p, std::span<const RunTile> tiles, uint64_t offset, size_t length,
                           FileAppender& appender) const {
    const OpenedPart& part = parts_[p];
    auto read_and_verify = [&](std::span<uint8_t> bytes) -> Result<void> {
      TESSERA_TRY(part.archive->source().read(offset, bytes));
      return verify(part, tiles, bytes);
    };
    if (length > kPayloadRunBytes) {
      // A single payload larger than the pool's buffers (a run holds at most one such): read
      // into an allocation of the appender's own and written on this thread.
      TESSERA_TRY(appender.appendFilled(length, read_and_verify));
      return {};
    }
    uint8_t* buffer = buffers_->take();
    OwnedBytes owned;
    owned.bytes = {buffer, length};
    owned.release = [buffers = buffers_, buffer] { buffers->giveBack(buffer); };
    Result<void> filled = read_and_verify({buffer, length});
    if (!filled) {
      owned.release();
      return filled;
    }
    TESSERA_TRY(appender.appendOwned(std::move(owned)));
    return {};
  }

  static Result<void> verify(const OpenedPart& part, std::span<const RunTile> tiles,
                             std::span<const uint8_t> bytes) {
    size_t at = 0;
    for (const RunTile& tile : tiles) {
      const uint32_t size = tile.entry->length_bytes;
      if (checksum64(bytes.subspan(at, size)) != tile.entry->checksum)
        return fail(ErrorCode::kCorrupt,
                    fmt::format("{}: tile ({},{},{}) fails its checksum", part.path,
                                tile.tile.level, tile.tile.x, tile.tile.y));
      at += size;
    }
    return {};
  }

  const std::vector<OpenedPart>& parts_;
  uint32_t merge_level_;
  const std::vector<std::vector<uint32_t>>& owner_;  ///< [level][tile row]: the part holding it
  const std::deque<std::vector<uint8_t>>& coarse_payloads_;  ///< by SpoolEntry::spool_offset
  std::shared_ptr<StretchBuffers> buffers_ = std::make_shared<StretchBuffers>();
};

}  // namespace

Result<MergeReport> mergeArchiveParts(const std::vector<std::string>& paths,
                                      const std::string& output, const std::atomic<bool>* cancel) {
  const auto start = std::chrono::steady_clock::now();
  TESSERA_TRY(checkOutputPath(output));
  TESSERA_ASSIGN_OR_RETURN(std::vector<OpenedPart> parts, openParts(paths));
  ImageInfo info = parts[0].archive->images()[0];
  const PartPlan plan = planParts(info, uint32_t(parts.size()));
  if (parts[0].merge_level != plan.merge_level)
    return fail(ErrorCode::kInvalidArgument,
                parts[0].path + ": split at another level than this version of tessera splits");
  SpooledImage out;
  out.info = info;
  out.entries.resize(info.level_count);
  for (uint32_t l = 0; l < info.level_count; ++l)
    out.entries[l].resize(size_t(info.tilesX(l)) * info.tilesY(l));
  std::vector<std::vector<uint32_t>> owner;
  TESSERA_TRY(copyPartEntries(parts, plan, out, owner));
  MergeReport report;
  auto phase_start = std::chrono::steady_clock::now();
  auto end_phase = [&](double& phase_s) {
    const auto now = std::chrono::steady_clock::now();
    phase_s = std::chrono::duration<double>(now - phase_start).count();
    phase_start = now;
  };
  report.open_s = std::chrono::duration<double>(phase_start - start).count();

  nlohmann::json metadata = parts[0].meta["archive_metadata"];
  ImageInfo level_info = info;
  level_info.width_px = info.levelWidthPx(plan.merge_level);
  level_info.height_px = info.levelHeightPx(plan.merge_level);
  level_info.level_count = info.level_count - plan.merge_level;
  const uint32_t threads = std::clamp(std::thread::hardware_concurrency(), 1u, 4u);
  TESSERA_ASSIGN_OR_RETURN(std::unique_ptr<WorkerPool> pool,
                           WorkerPool::start(threads, 2 * threads));
  CoarseSink sink(level_info, plan.merge_level, out, metadata["build"], *pool);
  Result<void> computed = [&]() -> Result<void> {
    PyramidBuilder pyramid(level_info, sink);
    return computeCoarseLevels(parts, info, plan.merge_level, pyramid);
  }();
  pool->waitIdle();  // queued jobs hold `sink`
  TESSERA_TRY(computed);
  TESSERA_TRY(sink.error());
  metadata["images"][0]["statistics"] = sink.statistics;
  if (cancel && cancel->load()) return fail(ErrorCode::kCancelled, output + ": merge cancelled");
  end_phase(report.coarse_s);

  TESSERA_ASSIGN_OR_RETURN(TempFile file, TempFile::create(output));
  PayloadCopier copier(parts, plan.merge_level, owner, sink.payloads);
  auto append = [&](std::span<const RunTile> run, size_t, FileAppender& appender) {
    if (cancel && cancel->load())
      return Result<void>(fail(ErrorCode::kCancelled, output + ": merge cancelled"));
    return copier.append(run, appender, report);
  };
  TESSERA_ASSIGN_OR_RETURN(
      WrittenArchive written,
      writeArchiveAppending(append, std::span<const SpooledImage>(&out, 1), buildOrderOf(metadata),
                            metadata, file, AppendWrites::kBackground));
  end_phase(report.copy_s);
  TESSERA_TRY(file.commit());
  end_phase(report.commit_s);
  report.output_bytes = written.file_bytes;
  report.tiles_computed = sink.payloads.size();
  report.elapsed_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

}  // namespace tessera
