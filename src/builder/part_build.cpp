// buildArchivePart: one share of a split build (docs/builder.md, "Split and merge").
#include <tessera/split_build.h>

#include <charconv>
#include <filesystem>
#include <system_error>

#include <fmt/format.h>

#include <tessera/archive.h>

#include "archive_writer.h"
#include "band_reader.h"
#include "build_internals.h"
#include "codecs/encode.h"
#include "builder/downsample.h"
#include "format/checksum.h"
#include "format/header.h"
#include "grid_reader.h"
#include "mosaic_manifest.h"
#include "output/output_file.h"
#include "part_build.h"
#include "part_plan.h"

namespace tessera {

using namespace detail;

namespace {

/// Parses the decimal text of one side of "I/N".
bool parseCount(std::string_view text, uint32_t& value) {
  if (text.empty()) return false;
  auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  return error == std::errc() && end == text.data() + text.size();
}

/// Level-0 rows in, the exact rows of level M out: the 2x2 averaging of the streaming pyramid,
/// row pair by row pair, with an odd last row averaged with itself at the image's end.
class RowDownsampler {
 public:
  RowDownsampler(const ImageInfo& info, uint32_t levels) : info_(info), levels_(levels) {
    pending_.resize(levels);
    scratch_.resize(levels);
  }
  void add(const uint8_t* row) { addAt(0, row); }
  /// At the image's end: the levels' odd last rows.
  void finish() {
    for (uint32_t l = 0; l < levels_; ++l) {
      if (pending_[l].empty()) continue;
      std::vector<uint8_t> last = std::move(pending_[l]);
      pending_[l].clear();
      emitPair(l, last.data(), last.data());
    }
  }
  std::vector<uint8_t> rows;  ///< level M rows, tightly packed

 private:
  void addAt(uint32_t level, const uint8_t* row) {
    const size_t row_bytes = size_t(info_.levelWidthPx(level)) * info_.channels;
    if (level == levels_) {
      rows.insert(rows.end(), row, row + row_bytes);
      return;
    }
    if (pending_[level].empty()) {
      pending_[level].assign(row, row + row_bytes);
      return;
    }
    std::vector<uint8_t> top = std::move(pending_[level]);
    pending_[level].clear();
    emitPair(level, top.data(), row);
  }
  void emitPair(uint32_t level, const uint8_t* top, const uint8_t* bottom) {
    std::vector<uint8_t>& out = scratch_[level];
    out.resize(size_t(info_.levelWidthPx(level + 1)) * info_.channels);
    downsampleRowPair(top, bottom, info_.levelWidthPx(level), info_.channels, info_.srgb_downsample,
                      out.data());
    addAt(level + 1, out.data());
  }

  const ImageInfo& info_;
  uint32_t levels_;
  std::vector<std::vector<uint8_t>> pending_;  ///< per level: a row waiting for its pair
  std::vector<std::vector<uint8_t>> scratch_;
};

/// What a file input is, so that the merge can tell that every part read the same file.
Result<nlohmann::json> inputIdentity(const std::string& input, const SourceInfo& source) {
  nlohmann::json identity = {{"source", input},
                             {"width", source.width_px},
                             {"height", source.height_px},
                             {"channels", source.channels}};
  if (input.rfind("synthetic:", 0) == 0) return identity;
  std::vector<std::string> files = {input};
  if (input.starts_with(kGridPrefix)) {  // every file of the grid, summed
    TESSERA_ASSIGN_OR_RETURN(GridSpec grid, parseGridSpec(input));
    files.clear();
    for (uint32_t row = 0; row < grid.rows; ++row)
      for (uint32_t column = 0; column < grid.columns; ++column)
        files.push_back(grid.path(column, row));
  }
  if (source.format == "mosaic") {  // the manifest and every image it names
    TESSERA_ASSIGN_OR_RETURN(MosaicManifest manifest, readMosaicManifest(input));
    for (const MosaicImage& image : manifest.images) files.push_back(image.path);
  }
  uint64_t bytes = 0;
  int64_t latest_ns = 0;
  for (const std::string& file : files) {
    std::error_code error;
    bytes += std::filesystem::file_size(file, error);
    const auto mtime = std::filesystem::last_write_time(file, error);
    if (error) return fail(ErrorCode::kIo, fmt::format("{}: {}", file, error.message()));
    latest_ns = std::max<int64_t>(
        latest_ns,
        std::chrono::duration_cast<std::chrono::nanoseconds>(mtime.time_since_epoch()).count());
  }
  identity["bytes"] = bytes;
  identity["mtime_ns"] = latest_ns;
  return identity;
}

/// The global image of a single-input build, as buildArchive's openSources makes it.
Result<ImageInfo> imageInfoFor(const BuildOptions& options, const SourceInfo& source) {
  ImageInfo info;
  info.width_px = source.width_px;
  info.height_px = source.height_px;
  info.channels = source.channels;
  info.tile_size_px = options.tile_size_px;
  info.border_px = options.border_px;
  info.page_tiles_log2 = options.page_tiles_log2;
  info.default_codec = options.codec;
  info.srgb_downsample = options.srgb_downsample;
  info.name = options.image_names.empty() ? displayName(options.inputs[0]) : options.image_names[0];
  TESSERA_TRY(validateImageInfo(info, options.inputs[0]));
  info.level_count = levelCountFor(info.width_px, info.height_px, info.tile_size_px);
  return info;
}

Result<void> checkPartRequest(const BuildOptions& options, PartSpec part) {
  if (part.count < 1 || part.count > kMaxBuildParts || part.index < 1 || part.index > part.count)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("--part {}/{}: want I/N with 1 <= I <= N <= {}", part.index, part.count,
                            kMaxBuildParts));
  if (options.inputs.size() != 1 || !options.row_sources.empty())
    return fail(ErrorCode::kInvalidArgument, "--part: a split build takes exactly one input image");
  if (options.codec == Codec::kPtm)
    return fail(ErrorCode::kInvalidArgument,
                "--part: codec ptm codes tiles against their parents, which another part "
                "computes; split builds take the other codecs");
  return {};
}

/// The part's own level-0 rows and the rows it reads around them.
struct PartRows {
  uint32_t first = 0, end = 0;                ///< owned: [first, end)
  uint32_t window_first = 0, window_end = 0;  ///< read and built: [window_first, window_end)
};

/// The window adds a band above and below for borders (tiles near the share's edge need the
/// neighbours' texels), and a band above a short last share so the window still reaches
/// level M - 1.
PartRows partRows(const ImageInfo& info, const PartPlan& plan, uint32_t part) {
  PartRows rows;
  rows.first = plan.firstRow(part);
  rows.end = plan.firstRow(part + 1);
  const bool short_share = rows.end - rows.first < plan.band_rows;
  const uint32_t above = info.border_px > 0 || short_share ? plan.band_rows : 0;
  const uint32_t below = info.border_px > 0 ? plan.band_rows : 0;
  rows.window_first = rows.first >= above ? rows.first - above : 0;
  rows.window_end = uint32_t(std::min<uint64_t>(info.height_px, uint64_t(rows.end) + below));
  return rows;
}

/// Builds the window [window_first, window_end) of `reader` as its own archive at `path`,
/// feeding the owned rows to `levels` as they pass.
Result<BuildReport> buildWindow(const BuildOptions& options, BandReader& reader,
                                const PartRows& rows, RowDownsampler& levels,
                                const std::string& path,
                                const std::function<void(const BuildProgress&)>& on_progress,
                                const std::atomic<bool>* cancel) {
  const SourceInfo& source = reader.info();
  const size_t row_bytes = size_t(source.width_px) * source.channels;
  uint32_t next_row = 0;  // the reader's position, in level-0 rows
  BuildOptions window = options;
  window.inputs.clear();
  window.image_names.clear();
  window.output = path;
  RowSource row_source;
  row_source.name = options.inputs[0];
  row_source.width_px = source.width_px;
  row_source.height_px = rows.window_end - rows.window_first;
  row_source.channels = source.channels;
  row_source.band_rows = source.natural_band_rows;
  row_source.read_rows = [&](uint32_t first, uint32_t count,
                             std::span<uint8_t> out) -> Result<void> {
    // Readers that seek (tiled and striped TIFF) read nothing above the window.
    if (next_row < rows.window_first) {
      TESSERA_TRY(reader.skipRows(rows.window_first - next_row));
      next_row = rows.window_first;
    }
    TESSERA_TRY(reader.readRows(count, out));
    next_row += count;
    for (uint32_t i = 0; i < count; ++i) {
      const uint32_t y = rows.window_first + first + i;
      if (y >= rows.first && y < rows.end) levels.add(out.data() + size_t(i) * row_bytes);
    }
    return {};
  };
  window.row_sources = {std::move(row_source)};
  return buildArchive(window, on_progress, cancel);
}

}  // namespace

Result<PartSpec> parsePartSpec(const std::string& text) {
  const size_t slash = text.find('/');
  PartSpec part;
  if (slash == std::string::npos ||
      !parseCount(std::string_view(text).substr(0, slash), part.index) ||
      !parseCount(std::string_view(text).substr(slash + 1), part.count) || part.index < 1 ||
      part.count < 1 || part.index > part.count || part.count > kMaxBuildParts)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("--part '{}': want I/N, parts counted from 1, with 1 <= I <= N <= {} "
                            "(e.g. 3/8)",
                            text, kMaxBuildParts));
  return part;
}

Result<BuildReport> buildArchivePart(const BuildOptions& options, PartSpec part,
                                     const std::function<void(const BuildProgress&)>& on_progress,
                                     const std::atomic<bool>* cancel) {
  TESSERA_TRY(checkPartRequest(options, part));
  TESSERA_TRY(validateBuildOptions(options));
  TESSERA_TRY(checkOutputPath(options.output));
  TESSERA_ASSIGN_OR_RETURN(std::unique_ptr<BandReader> reader, openBandReader(options.inputs[0]));
  // The parts' rows and the merge's coarse levels are averaged as 8-bit texels.
  if (reader->info().sample_type != SampleType::kU8)
    return fail(ErrorCode::kUnsupported,
                fmt::format("{}: {} samples; --part splits 8-bit images (build wider ones whole)",
                            options.inputs[0], sampleTypeName(reader->info().sample_type)));
  TESSERA_ASSIGN_OR_RETURN(ImageInfo info, imageInfoFor(options, reader->info()));
  TESSERA_ASSIGN_OR_RETURN(nlohmann::json identity,
                           inputIdentity(options.inputs[0], reader->info()));
  const PartPlan plan = planParts(info, part.count);
  const PartRows rows = partRows(info, plan, part.index - 1);

  RowDownsampler levels(info, plan.merge_level);
  BuildReport report;
  PartLayout layout{info, plan, rows.first, rows.end, rows.window_first};
  std::shared_ptr<Archive> window;
  const std::string window_path = options.output + ".window";
  struct RemoveWindow {
    const std::string& path;
    ~RemoveWindow() {
      std::error_code ignored;
      std::filesystem::remove(path, ignored);
    }
  } remove_window{window_path};
  if (rows.end > rows.first && plan.merge_level > 0) {
    TESSERA_ASSIGN_OR_RETURN(
        report, buildWindow(options, *reader, rows, levels, window_path, on_progress, cancel));
    TESSERA_ASSIGN_OR_RETURN(window, Archive::openFile(window_path));
  } else if (rows.end > rows.first) {
    std::vector<uint8_t> all(size_t(info.width_px) * info.channels * info.height_px);
    TESSERA_TRY(reader->readRows(info.height_px, all));
    for (uint32_t y = 0; y < info.height_px; ++y)
      levels.add(all.data() + size_t(y) * info.width_px * info.channels);
  }
  if (rows.end == info.height_px) levels.finish();
  nlohmann::json image_meta = imageMetadata(info, options.inputs[0], reader->info(), nullptr);
  nlohmann::json part_meta = {
      {"index", part.index},
      {"count", part.count},
      {"merge_level", plan.merge_level},
      {"rows", {rows.first, rows.end}},
      {"input", identity},
      {"image", info.name},
      {"page_tiles_log2", info.page_tiles_log2},
      {"stored_bytes_read", reader->storedBytesRead()},
      {"archive_metadata", archiveMetadata(options, nlohmann::json::array({image_meta}))}};
  TESSERA_ASSIGN_OR_RETURN(uint64_t bytes, writePartArchive(layout, window.get(), levels.rows,
                                                            part_meta, options.output));
  report.output_bytes = bytes;
  report.images = {info};
  return report;
}

}  // namespace tessera
