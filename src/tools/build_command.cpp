// `tessera build`: source image(s) -> archive.
#include <csignal>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <tessera/build.h>

#include "cli.h"
#include "procedural_cli.h"

namespace tessera::cli {

namespace {

std::atomic<bool> g_interrupted{false};

extern "C" void onInterrupt(int) {
  g_interrupted.store(true);
}

struct BuildArgs {
  BuildOptions options;
  std::string codec = "jpeg";
  std::string order = "hilbert";
  std::string chroma = "420";
  bool quiet = false;
  bool json = false;
};

int runBuild(BuildArgs& args) {
  if (!parseCodecName(args.codec, &args.options.codec))
    return reportError({ErrorCode::kInvalidArgument, "unknown codec " + args.codec});
  if (args.order == "hilbert")
    args.options.order = TileOrder::kHilbert;
  else if (args.order == "quadtree")
    args.options.order = TileOrder::kQuadtree;
  else if (args.order == "row-major")
    args.options.order = TileOrder::kRowMajor;
  else
    return reportError({ErrorCode::kInvalidArgument, "unknown order " + args.order});
  args.options.chroma_subsampling = args.chroma == "420";

  // Ctrl-C cancels cleanly: the builder removes its temporaries and leaves no output.
  struct sigaction action {};
  action.sa_handler = onInterrupt;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);

  bool show_progress = !args.quiet && !args.json && stderrIsTerminal();
  ProgressBar bar("building");
  auto on_progress = [&](const BuildProgress& progress) {
    if (show_progress)
      bar.update(double(progress.pixels_done), double(progress.pixels_total), progress.elapsed_s,
                 1e6, "MP/s");
  };
  Result<BuildReport> report = buildArchive(args.options, on_progress, &g_interrupted);
  bar.finish();
  if (!report) return reportError(report.error());
  if (args.json) {
    nlohmann::json out = {
        {"output", args.options.output},          {"output_bytes", report->output_bytes},
        {"payload_bytes", report->payload_bytes}, {"tiles_encoded", report->tiles_encoded},
        {"tiles_uniform", report->tiles_uniform}, {"tiles_empty", report->tiles_empty},
        {"elapsed_s", report->elapsed_s},         {"megapixels_per_s", report->megapixels_per_s}};
    std::printf("%s\n", out.dump(2).c_str());
  } else if (!args.quiet) {
    uint64_t pixels = 0;
    for (const ImageInfo& image : report->images)
      pixels += uint64_t(image.width_px) * image.height_px;
    std::printf(
        "%s: %zu image(s), %.1f MP, %s in %.2f s (%.1f MP/s); tiles: %llu encoded, %llu "
        "uniform, %llu empty\n",
        args.options.output.c_str(), report->images.size(), pixels / 1e6,
        formatBytes(report->output_bytes).c_str(), report->elapsed_s, report->megapixels_per_s,
        (unsigned long long)report->tiles_encoded, (unsigned long long)report->tiles_uniform,
        (unsigned long long)report->tiles_empty);
  }
  return kExitOk;
}

}  // namespace

void registerBuildCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<BuildArgs>();
  CLI::App* cmd = app.add_subcommand("build",
                                     "Build an archive from TIFF/BigTIFF, PNG, JPEG or "
                                     "synthetic:WxH[:seed[:channels]]");
  cmd->add_option("inputs", args->options.inputs, "Source image(s); several make a texture set");
  cmd->add_option("-o,--output", args->options.output, "Archive to write (atomically)")->required();
  cmd->add_option("--tile", args->options.tile_size_px,
                  "Tile size in pixels (power of two, 64..2048)")
      ->capture_default_str();
  cmd->add_option("--border", args->options.border_px, "Border texels per tile side (0..16)")
      ->capture_default_str();
  cmd->add_option(
         "--codec", args->codec,
         "raw, zstd, lz4, jpeg, png, webp or ptm (lossless, coded against the parent level)")
      ->capture_default_str();
  cmd->add_option("--quality", args->options.quality, "JPEG quality (1..100)")
      ->capture_default_str();
  cmd->add_option("--effort", args->options.effort,
                  "Codec effort: zstd level, PNG/WebP effort, ptm mode 1-4 (0 = codec default)")
      ->capture_default_str();
  cmd->add_option("--chroma", args->chroma, "JPEG chroma subsampling: 420 or 444")
      ->check(CLI::IsMember({"420", "444"}))
      ->capture_default_str();
  cmd->add_flag("--srgb", args->options.srgb_downsample, "Average levels in linear light");
  cmd->add_option("--order", args->order, "Payload order: hilbert, quadtree or row-major")
      ->capture_default_str();
  cmd->add_option("--threads", args->options.threads, "Encoder threads (0 = all cores)")
      ->capture_default_str();
  cmd->add_option("--page-tiles-log2", args->options.page_tiles_log2,
                  "Directory page side as a power of two of tiles (3..8)")
      ->capture_default_str();
  cmd->add_option("--name", args->options.image_names, "Image name(s), one per input");
  cmd->add_flag("-q,--quiet", args->quiet, "No progress and no summary");
  cmd->add_flag("--json", args->json, "Print the build report as JSON");
  auto procedural = addProceduralBuildOptions(cmd);
  cmd->callback([args, procedural, &exit_code] {
    exit_code = procedural->requested() ? runProceduralBuild(*procedural, args->options,
                                                             args->codec, args->quiet, args->json)
                                        : runBuild(*args);
  });
}

}  // namespace tessera::cli
