// buildProceduralArchive: brush database -> analysis of every tile -> storage choice -> mixed
// archive (Demeulemeester et al., section 2; docs/procedural.md, "The analysis phase").
#include <tessera/procedural_build.h>

#include <algorithm>
#include <chrono>
#include <filesystem>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <tessera/brushes.h>

#include "base_layer.h"
#include "codecs/encode.h"
#include "format/procedural.h"
#include "tile_pass.h"

namespace tessera {

using namespace detail;

namespace {

using Clock = std::chrono::steady_clock;

Result<void> validateOptions(const ProceduralBuildOptions& options) {
  if (options.database.empty()) return fail(ErrorCode::kInvalidArgument, "no brush database given");
  if (options.output.empty()) return fail(ErrorCode::kInvalidArgument, "no output path given");
  if (codecNeedsParent(options.codec))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("codec {} codes tiles against their parents, which may be procedural; "
                            "choose another for a procedural build",
                            codecName(options.codec)));
  if (!codecIsLossless(options.brush_codec) || codecNeedsParent(options.brush_codec))
    return fail(ErrorCode::kInvalidArgument, "brush images need a lossless codec");
  if (!findEncoder(options.codec) || !findEncoder(options.brush_codec))
    return fail(ErrorCode::kUnsupported, "codec not available in this build");
  if (options.quality < 1 || options.quality > 100)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("quality {} out of 1..100", options.quality));
  if (!(options.frame_budget_ms > 0) || options.max_new_tiles_per_frame == 0)
    return fail(ErrorCode::kInvalidArgument,
                "the frame budget and the new tiles per frame must be positive");
  return {};
}
Result<MixedPicture> encodePicture(const Image& image, Codec codec, const std::string& what) {
  MixedPicture picture;
  Result<std::vector<uint8_t>> payload = encodeTile(codec, image.view(), EncodeOptions{});
  if (!payload) return fail(payload.error().code, what + ": " + payload.error().message);
  picture.payload = std::move(*payload);
  picture.width_px = image.width_px;
  picture.height_px = image.height_px;
  picture.channels = image.channels;
  picture.codec = codec;
  return picture;
}

// The detail regions as a grid of cells of the coarsest tile size that resolves them.
DetailMap detailMapOf(const ProceduralBuildOptions& options, const ImageInfo& info) {
  DetailMap map;
  if (options.detail_regions.empty()) return map;
  map.cell_px = info.tile_size_px;
  map.columns = (info.width_px + map.cell_px - 1) / map.cell_px;
  map.rows = (info.height_px + map.cell_px - 1) / map.cell_px;
  map.finest_level.assign(size_t(map.columns) * map.rows, 0);
  for (uint32_t y = 0; y < map.rows; ++y) {
    for (uint32_t x = 0; x < map.columns; ++x) {
      const BoxPx cell{double(x) * map.cell_px, double(y) * map.cell_px,
                       double(x + 1) * map.cell_px, double(y + 1) * map.cell_px};
      for (const DetailRegion& region : options.detail_regions)
        // A cell takes a region's level only when the region covers it whole.
        if (region.area.x0 <= cell.x0 && region.area.y0 <= cell.y0 && region.area.x1 >= cell.x1 &&
            region.area.y1 >= cell.y1)
          map.finest_level[size_t(y) * map.columns + x] = uint8_t(std::max<uint32_t>(
              map.finest_level[size_t(y) * map.columns + x], std::min(region.finest_level, 255u)));
    }
  }
  return map;
}

/// Brushes, the layer and the texture size from the database and --base; every brush image
/// encoded once up front (its stored size is its cost in the storage choice).
struct PreparedInputs {
  std::shared_ptr<const BrushSet> set;
  std::vector<std::vector<MixedPicture>> pictures;  ///< per brush
  std::optional<MixedPicture> layer;
  uint64_t instances = 0;
};

Result<PreparedInputs> prepareInputs(const ProceduralBuildOptions& options, ImageInfo& info) {
  TESSERA_ASSIGN_OR_RETURN(std::unique_ptr<BrushDatabase> database,
                           openBrushDatabase(options.database, false));
  TESSERA_ASSIGN_OR_RETURN(std::vector<Brush> brushes, database->brushes());
  TESSERA_ASSIGN_OR_RETURN(TextureExtent extent, database->textureExtent());
  PreparedInputs inputs;
  TESSERA_ASSIGN_OR_RETURN(inputs.instances, database->instanceCount());
  if (brushes.empty())
    return fail(ErrorCode::kInvalidArgument, options.database + ": the database has no brushes");
  UnderlyingLayer layer;
  if (!options.base.empty()) {
    TESSERA_ASSIGN_OR_RETURN(
        BaseLayer base,
        loadBaseLayer(options.base, std::filesystem::path(options.output).parent_path().string()));
    if (extent.width_px == 0) extent = {base.source_width_px, base.source_height_px};
    TESSERA_ASSIGN_OR_RETURN(MixedPicture picture,
                             encodePicture(base.height, options.brush_codec, options.base));
    inputs.layer = std::move(picture);
    layer.height = std::move(base.height);
  }
  if (extent.width_px == 0 || extent.height_px == 0)
    return fail(ErrorCode::kInvalidArgument,
                options.database +
                    ": no texture size (set it with tessera brushes init --size, or "
                    "give --base)");
  info.width_px = extent.width_px;
  info.height_px = extent.height_px;
  for (size_t b = 0; b < brushes.size(); ++b) {
    std::vector<MixedPicture> pictures;
    for (size_t v = 0; v < brushes[b].images.size(); ++v) {
      TESSERA_ASSIGN_OR_RETURN(MixedPicture picture,
                               encodePicture(brushes[b].images[v], options.brush_codec,
                                             fmt::format("{}: brush {} image {}", options.database,
                                                         brushes[b].name, v)));
      pictures.push_back(std::move(picture));
    }
    inputs.pictures.push_back(std::move(pictures));
  }
  TESSERA_ASSIGN_OR_RETURN(inputs.set, BrushSet::prepare(std::move(brushes), std::move(layer),
                                                         extent.width_px, extent.height_px));
  return inputs;
}

// The storage problem of the tile pass: one resource per brush (its images and records) and
// one for the layer.
StorageProblem storageProblem(BuildContext& context, const PreparedInputs& inputs) {
  StorageProblem problem;
  problem.tiles = std::move(context.storage);
  for (const auto& pictures : inputs.pictures) {
    uint64_t bytes = kBrushRecordBytes;
    for (const MixedPicture& picture : pictures)
      bytes += picture.payload.size() + kProceduralImageRecordBytes;
    problem.resource_bytes.push_back(bytes);
  }
  problem.resource_bytes.push_back(
      inputs.layer ? inputs.layer->payload.size() + kProceduralImageRecordBytes : 0);
  return problem;
}

// Applies the choice to the tiles and gathers the stored brushes, renumbered.
MixedBrushes applyChoice(BuildContext& context, const StorageChoice& choice,
                         PreparedInputs& inputs) {
  uint64_t flat = 0;
  for (auto& level : context.tiles)
    for (MixedTile& tile : level) tile.procedural = choice.procedural[flat++];
  MixedBrushes stored;
  stored.remap.assign(inputs.pictures.size(), -1);
  for (size_t b = 0; b < inputs.pictures.size(); ++b) {
    if (!choice.resource_stored[b]) continue;
    const Brush& brush = context.set->brushes()[b];
    stored.remap[b] = int64_t(stored.brushes.size());
    ProceduralBrushRecord record;
    record.image_first = uint32_t(stored.pictures.size());
    record.image_count = uint32_t(inputs.pictures[b].size());
    record.blend = brush.blend;
    record.mask = brush.mask;
    record.mask_low = brush.mask_low;
    record.mask_high = brush.mask_high;
    stored.brushes.push_back(record);
    for (MixedPicture& picture : inputs.pictures[b]) stored.pictures.push_back(std::move(picture));
  }
  if (choice.resource_stored.back() && inputs.layer) stored.layer = std::move(inputs.layer);
  return stored;
}

nlohmann::json metadataOf(const ProceduralBuildOptions& options,
                          const ProceduralBuildReport& report, const std::vector<Brush>& brushes,
                          bool procedural) {
  nlohmann::json names = nlohmann::json::array();
  for (const Brush& brush : brushes) names.push_back(brush.name);
  return {{"format", "tessera"},
          {"format_version", procedural ? "1.1" : "1.0"},
          {"created_by", "tessera build --procedural"},
          {"build",
           {{"tile_size", options.tile_size_px},
            {"border", options.border_px},
            {"codec", codecName(options.codec)},
            {"quality", options.quality},
            {"downsample", "composited per level"}}},
          {"images",
           {{{"name", std::filesystem::path(options.database).filename().string()},
             {"source", options.database},
             {"source_format", "brush database"},
             {"width", report.image.width_px},
             {"height", report.image.height_px},
             {"channels", 4}}}},
          {"procedural",
           {{"brushes", names},
            {"tiles_procedural", report.tiles_procedural},
            {"tiles_baked", report.tiles_baked},
            {"tile_budget_ms", report.tile_budget_ms},
            {"worst_estimated_ms", report.worst_estimated_ms}}}};
}

void summarise(const BuildContext& context, const StorageProblem& problem,
               const StorageChoice& choice, ProceduralBuildReport& report) {
  report.tiles_dropped = context.dropped;
  report.instances_queried = context.queried;
  report.instances_covered = context.covered;
  report.instances_small = context.small;
  report.mean_query_us =
      report.tiles_total ? double(context.query_ns) / 1e3 / double(report.tiles_total) : 0;
  uint64_t flat = 0;
  for (const auto& level : context.tiles) {
    for (const MixedTile& tile : level) {
      const StorageTile& storage = problem.tiles[flat];
      report.all_baked_payload_bytes += storage.baked_bytes;
      if (choice.procedural[flat]) {
        ++report.tiles_procedural;
        report.worst_estimated_ms = std::max(report.worst_estimated_ms, context.estimated_ms[flat]);
        report.worst_measured_ms = std::max(report.worst_measured_ms, context.measured_ms[flat]);
      } else if (tile.baked_kind == TileKind::kEncoded) {
        ++report.tiles_baked;
        if (tile.has_page && !storage.eligible) ++report.tiles_over_budget;
      } else if (tile.baked_kind == TileKind::kUniform) {
        ++report.tiles_uniform;
      } else {
        ++report.tiles_empty;
      }
      ++flat;
    }
  }
}

}  // namespace

Result<ProceduralBuildReport> buildProceduralArchive(
    const ProceduralBuildOptions& options,
    const std::function<void(const ProceduralBuildProgress&)>& on_progress,
    const std::atomic<bool>* cancel) {
  const auto start = Clock::now();
  TESSERA_TRY(validateOptions(options));
  BuildContext context;
  context.options = &options;
  context.cancel = cancel;
  context.info.channels = 4;
  context.info.tile_size_px = options.tile_size_px;
  context.info.border_px = options.border_px;
  context.info.page_tiles_log2 = options.page_tiles_log2;
  context.info.default_codec = options.codec;
  TESSERA_ASSIGN_OR_RETURN(PreparedInputs inputs, prepareInputs(options, context.info));
  TESSERA_TRY(validateImageInfo(context.info, options.output));
  context.info.level_count =
      levelCountFor(context.info.width_px, context.info.height_px, context.info.tile_size_px);
  context.set = inputs.set;
  context.resource_layer = uint32_t(inputs.pictures.size());
  context.detail = detailMapOf(options, context.info);
  context.rules.detail = &context.detail;
  context.rules.small_instance_texels = options.small_instance_texels;
  context.rules.cost = {options.cost_tile_ns, options.cost_instance_ns, options.cost_texel_ns};
  context.rules.tile_budget_ms = options.frame_budget_ms / options.max_new_tiles_per_frame;
  uint64_t total = 0;
  context.tiles.resize(context.info.level_count);
  for (uint32_t l = 0; l < context.info.level_count; ++l) {
    context.level_first.push_back(total);
    const uint64_t count = uint64_t(context.info.tilesX(l)) * context.info.tilesY(l);
    context.tiles[l].resize(count);
    total += count;
  }
  context.storage.resize(total);
  context.estimated_ms.assign(total, 0);
  context.measured_ms.assign(total, 0);

  TESSERA_ASSIGN_OR_RETURN(TempFile spool, TempFile::create(options.output));
  TESSERA_ASSIGN_OR_RETURN(TempFile out, TempFile::create(options.output));
  context.spool = &spool;
  TESSERA_TRY(runTilePass(context, on_progress, start));

  StorageProblem problem = storageProblem(context, inputs);
  StorageChoice choice = chooseStorage(problem);
  if (options.bake_all) {
    StorageChoice baked;
    baked.procedural.assign(problem.tiles.size(), false);
    baked.resource_stored.assign(problem.resource_bytes.size(), false);
    baked.total_bytes = storageCost(problem, baked.procedural);
    choice = std::move(baked);
  }
  ProceduralBuildReport report;
  report.image = context.info;
  report.tiles_total = total;
  report.instances = inputs.instances;
  report.tile_budget_ms = context.rules.tile_budget_ms;
  summarise(context, problem, choice, report);
  const std::vector<Brush> brush_list = context.set->brushes();
  MixedBrushes stored = applyChoice(context, choice, inputs);
  const bool procedural = report.tiles_procedural > 0;
  TESSERA_ASSIGN_OR_RETURN(
      MixedWritten written,
      writeMixedArchive(spool, context.info, context.tiles, stored, options.order,
                        metadataOf(options, report, brush_list, procedural), out));
  if (cancel && cancel->load())
    return fail(ErrorCode::kCancelled, options.output + ": build cancelled");
  TESSERA_TRY(out.commit());
  report.baked_payload_bytes = written.baked_payload_bytes;
  report.procedural_page_bytes = written.page_bytes;
  report.brush_bytes = written.brush_bytes;
  report.bytes_saved =
      int64_t(report.all_baked_payload_bytes) -
      int64_t(written.baked_payload_bytes + written.page_bytes + written.brush_bytes);
  report.output_bytes = written.file_bytes;
  report.elapsed_s = std::chrono::duration<double>(Clock::now() - start).count();
  return report;
}

}  // namespace tessera
