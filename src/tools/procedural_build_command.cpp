// `tessera build --procedural DB [--base image.tif]`: a mixed archive from a brush database,
// with the analysis phase's report (docs/procedural.md, "The analysis phase").
#include <csignal>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <tessera/procedural_build.h>

#include "cli.h"
#include "procedural_cli.h"

namespace tessera::cli {

namespace {

std::atomic<bool> g_procedural_interrupted{false};

extern "C" void onProceduralInterrupt(int) {
  g_procedural_interrupted.store(true);
}

Result<DetailRegion> parseDetailRegion(const std::string& text) {
  DetailRegion region;
  char tail = 0;
  if (std::sscanf(text.c_str(), "%lf,%lf,%lf,%lf:%u%c", &region.area.x0, &region.area.y0,
                  &region.area.x1, &region.area.y1, &region.finest_level, &tail) != 5)
    return fail(ErrorCode::kInvalidArgument,
                "--detail-region " + text + ": expected x0,y0,x1,y1:finest_level");
  return region;
}

nlohmann::json reportJson(const ProceduralBuildReport& r, const std::string& output) {
  return {{"output", output},
          {"output_bytes", r.output_bytes},
          {"width", r.image.width_px},
          {"height", r.image.height_px},
          {"levels", r.image.level_count},
          {"tiles_total", r.tiles_total},
          {"tiles_procedural", r.tiles_procedural},
          {"tiles_baked", r.tiles_baked},
          {"tiles_uniform", r.tiles_uniform},
          {"tiles_empty", r.tiles_empty},
          {"tiles_dropped", r.tiles_dropped},
          {"tiles_over_budget", r.tiles_over_budget},
          {"instances", r.instances},
          {"instances_queried", r.instances_queried},
          {"instances_covered", r.instances_covered},
          {"instances_small", r.instances_small},
          {"baked_payload_bytes", r.baked_payload_bytes},
          {"procedural_page_bytes", r.procedural_page_bytes},
          {"brush_bytes", r.brush_bytes},
          {"all_baked_payload_bytes", r.all_baked_payload_bytes},
          {"bytes_saved", r.bytes_saved},
          {"tile_budget_ms", r.tile_budget_ms},
          {"worst_estimated_ms", r.worst_estimated_ms},
          {"worst_measured_ms", r.worst_measured_ms},
          {"mean_query_us", r.mean_query_us},
          {"elapsed_s", r.elapsed_s}};
}

void printReport(const ProceduralBuildReport& r, const std::string& output) {
  std::printf("%s: %ux%u, %s in %.1f s\n", output.c_str(), r.image.width_px, r.image.height_px,
              formatBytes(r.output_bytes).c_str(), r.elapsed_s);
  std::printf(
      "  tiles: %llu procedural, %llu baked (%llu over the %.3f ms budget), %llu uniform, "
      "%llu empty (%llu dropped levels)\n",
      (unsigned long long)r.tiles_procedural, (unsigned long long)r.tiles_baked,
      (unsigned long long)r.tiles_over_budget, r.tile_budget_ms,
      (unsigned long long)r.tiles_uniform, (unsigned long long)r.tiles_empty,
      (unsigned long long)r.tiles_dropped);
  std::printf(
      "  bytes: %s baked payloads + %s instance pages + %s brushes, against %s all "
      "baked: %s saved\n",
      formatBytes(r.baked_payload_bytes).c_str(), formatBytes(r.procedural_page_bytes).c_str(),
      formatBytes(r.brush_bytes).c_str(), formatBytes(r.all_baked_payload_bytes).c_str(),
      r.bytes_saved >= 0 ? formatBytes(uint64_t(r.bytes_saved)).c_str()
                         : ("-" + formatBytes(uint64_t(-r.bytes_saved))).c_str());
  std::printf(
      "  worst compositing time of a procedural tile: %.3f ms estimated, %.3f ms measured\n",
      r.worst_estimated_ms, r.worst_measured_ms);
  std::printf(
      "  instances: %llu in the database; per tile %llu queried, %llu covered, %llu too "
      "small; %.1f us per query\n",
      (unsigned long long)r.instances, (unsigned long long)r.instances_queried,
      (unsigned long long)r.instances_covered, (unsigned long long)r.instances_small,
      r.mean_query_us);
}

}  // namespace

std::shared_ptr<ProceduralBuildFlags> addProceduralBuildOptions(CLI::App* build) {
  auto flags = std::make_shared<ProceduralBuildFlags>();
  build->add_option("--procedural", flags->database,
                    "Build a mixed archive from a brush database (SQLite file or PostGIS "
                    "connection) instead of inputs");
  build->add_option("--base", flags->base,
                    "With --procedural: the underlying height image read by masked brushes");
  build
      ->add_option("--frame-budget-ms", flags->frame_budget_ms,
                   "With --procedural: compositing time allowed per frame")
      ->capture_default_str();
  build
      ->add_option("--max-new-tiles", flags->max_new_tiles,
                   "With --procedural: most tiles a frame brings into view")
      ->capture_default_str();
  build
      ->add_option("--small-instance-texels", flags->small_instance_texels,
                   "With --procedural: drop instances narrower than this fraction of a texel of "
                   "the finest stored level (0 keeps all)")
      ->capture_default_str();
  build
      ->add_option("--cost-texel-ns", flags->cost_texel_ns,
                   "With --procedural: the cost model's time per texel visited")
      ->capture_default_str();
  build->add_option(
      "--detail-region", flags->detail_regions,
      "With --procedural: x0,y0,x1,y1:LEVEL, levels finer than LEVEL not stored there");
  build->add_flag("--bake-all", flags->bake_all,
                  "With --procedural: store every tile baked (for comparison)");
  return flags;
}

int runProceduralBuild(const ProceduralBuildFlags& flags, const BuildOptions& common,
                       const std::string& codec, bool quiet, bool json) {
  ProceduralBuildOptions options;
  options.database = flags.database;
  options.base = flags.base;
  options.output = common.output;
  options.tile_size_px = common.tile_size_px;
  options.border_px = common.border_px;
  options.quality = common.quality;
  options.effort = common.effort;
  options.threads = common.threads;
  options.page_tiles_log2 = common.page_tiles_log2;
  options.order = common.order;
  options.frame_budget_ms = flags.frame_budget_ms;
  options.max_new_tiles_per_frame = flags.max_new_tiles;
  options.small_instance_texels = flags.small_instance_texels;
  options.cost_texel_ns = flags.cost_texel_ns;
  options.bake_all = flags.bake_all;
  if (!common.inputs.empty())
    return reportError({ErrorCode::kInvalidArgument,
                        "--procedural builds from the database: give no input images"});
  if (!parseCodecName(codec, &options.codec))
    return reportError({ErrorCode::kInvalidArgument, "unknown codec " + codec});
  for (const std::string& text : flags.detail_regions) {
    Result<DetailRegion> region = parseDetailRegion(text);
    if (!region) return reportError(region.error());
    options.detail_regions.push_back(*region);
  }
  struct sigaction action {};
  action.sa_handler = onProceduralInterrupt;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
  bool show_progress = !quiet && !json && stderrIsTerminal();
  ProgressBar bar("analysing");
  auto on_progress = [&](const ProceduralBuildProgress& progress) {
    if (show_progress)
      bar.update(double(progress.tiles_done), double(progress.tiles_total), progress.elapsed_s, 1,
                 "tiles/s");
  };
  Result<ProceduralBuildReport> report =
      buildProceduralArchive(options, on_progress, &g_procedural_interrupted);
  bar.finish();
  if (!report) return reportError(report.error());
  if (json)
    std::printf("%s\n", reportJson(*report, options.output).dump(2).c_str());
  else if (!quiet)
    printReport(*report, options.output);
  return kExitOk;
}

}  // namespace tessera::cli
