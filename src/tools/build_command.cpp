// `tessera build`: source image(s) -> archive.
#include <algorithm>
#include <csignal>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <tessera/build.h>
#include <tessera/split_build.h>

#include "cli.h"
#include "procedural_cli.h"
#include "output/output_file.h"
#include "scene_command.h"

namespace tessera::cli {

namespace {

std::atomic<bool> g_interrupted{false};
std::atomic<int> g_signal{0};  ///< the signal that interrupted the build, for its exit code

extern "C" void onInterrupt(int signal) {
  g_signal.store(signal);
  g_interrupted.store(true);
}

struct BuildArgs {
  BuildOptions options;
  std::string codec = "jpeg";
  std::string order = "hilbert";
  std::string chroma = "420";
  std::string memory_limit;  ///< SIZE; empty = the default
  std::string part;          ///< --part I/N; empty = the whole build
  bool quiet = false;
  bool json = false;
};

/// `text` lower-cased, with '_' and ' ' read as '-': the spellings people type for one value.
std::string canonicalSpelling(std::string text) {
  for (char& c : text) c = c == '_' || c == ' ' ? '-' : char(std::tolower(uint8_t(c)));
  return text;
}

/// A value with its accepted spellings; the first is the documented one.
struct Choice {
  std::vector<std::string> spellings;
};

/// The index of the choice `text` spells, or an "unknown value" error that lists them all.
Result<size_t> pickChoice(const char* option, const std::string& text,
                          const std::vector<Choice>& choices) {
  const std::string wanted = canonicalSpelling(text);
  std::vector<std::string> names;
  for (size_t i = 0; i < choices.size(); ++i) {
    for (const std::string& spelling : choices[i].spellings)
      if (wanted == spelling) return i;
    names.push_back(choices[i].spellings.front());
  }
  const std::string nearest = nearestName(wanted, names);
  return fail(ErrorCode::kInvalidArgument,
              fmt::format("{} '{}' is not one of {}{}", option, text, listChoices(names),
                          nearest.empty() ? "" : fmt::format(" (did you mean '{}'?)", nearest)));
}

/// The spelt values of --codec, --order and --chroma into `args.options`.
Result<void> resolveChoices(BuildArgs& args) {
  static const Codec kCodecs[] = {Codec::kRaw, Codec::kZstd, Codec::kLz4, Codec::kJpeg,
                                  Codec::kPng, Codec::kWebp, Codec::kPtm, Codec::kZdelta,
                                  Codec::kBc1, Codec::kBc7};
  static const std::vector<Choice> kCodecChoices = {{{"raw", "none", "uncompressed"}},
                                                    {{"zstd", "zst", "zstandard"}},
                                                    {{"lz4"}},
                                                    {{"jpeg", "jpg"}},
                                                    {{"png"}},
                                                    {{"webp", "webp-lossless"}},
                                                    {{"ptm"}},
                                                    {{"zdelta"}},
                                                    {{"bc1", "dxt1"}},
                                                    {{"bc7", "bptc"}}};
  TESSERA_ASSIGN_OR_RETURN(size_t codec, pickChoice("--codec", args.codec, kCodecChoices));
  args.options.codec = kCodecs[codec];
  static const TileOrder kOrders[] = {TileOrder::kHilbert, TileOrder::kQuadtree,
                                      TileOrder::kRowMajor};
  static const std::vector<Choice> kOrderChoices = {
      {{"hilbert"}}, {{"quadtree", "quad-tree"}}, {{"row-major", "rowmajor", "raster"}}};
  TESSERA_ASSIGN_OR_RETURN(size_t order, pickChoice("--order", args.order, kOrderChoices));
  args.options.order = kOrders[order];
  static const std::vector<Choice> kChromaChoices = {{{"420", "4:2:0"}}, {{"444", "4:4:4"}}};
  TESSERA_ASSIGN_OR_RETURN(size_t chroma, pickChoice("--chroma", args.chroma, kChromaChoices));
  args.options.chroma_subsampling = chroma == 0;
  if (!args.memory_limit.empty()) {
    TESSERA_ASSIGN_OR_RETURN(args.options.memory_limit_bytes,
                             parseByteSize("--memory-limit", args.memory_limit));
  }
  return {};
}

/// A build stopped by a signal exits 128 + its number: 130 for SIGINT, 143 for SIGTERM.
int reportBuildError(const Error& error) {
  const int code = reportError(error);
  if (error.code != ErrorCode::kCancelled) return code;
  return g_signal.load() == SIGTERM ? int(kExitTerminated) : int(kExitCancelled);
}

int runBuild(BuildArgs& args) {
  if (Result<void> resolved = resolveChoices(args); !resolved) return reportError(resolved.error());
  if (Result<void> valid = validateBuildOptions(args.options); !valid)
    return reportError(valid.error());
  // Before any input is read: `-o /dev/null` or a FIFO is refused, never replaced.
  if (Result<void> output = detail::checkOutputPath(args.options.output); !output)
    return reportError(output.error());

  // Ctrl-C cancels cleanly: the builder removes its temporaries and leaves no output.
  struct sigaction action {};
  action.sa_handler = onInterrupt;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);

  if (isSceneBuild(args.options)) {
    if (args.options.memory_limit_bytes != 0 || !args.options.spool_dir.empty())
      return reportError({ErrorCode::kInvalidArgument,
                          "--memory-limit and --spool-dir apply to image builds; a scene build "
                          "bounds each texture with --max-texture-side (docs/scenes.md)"});
    const int code = runSceneBuild(args.options, args.quiet, args.json, &g_interrupted);
    if (code == kExitCancelled && g_signal.load() == SIGTERM) return kExitTerminated;
    return code;
  }
  bool show_progress = !args.quiet && !args.json && stderrIsTerminal();
  ProgressBar bar("building");
  auto on_progress = [&](const BuildProgress& progress) {
    if (show_progress)
      bar.update(double(progress.pixels_done), double(progress.pixels_total), progress.elapsed_s,
                 1e6, "MP/s");
  };
  Result<PartSpec> part = args.part.empty() ? PartSpec{} : parsePartSpec(args.part);
  if (!part) return reportError(part.error());
  Result<BuildReport> report =
      args.part.empty() ? buildArchive(args.options, on_progress, &g_interrupted)
                        : buildArchivePart(args.options, *part, on_progress, &g_interrupted);
  bar.finish();
  if (!report) return reportBuildError(report.error());
  if (args.json) {
    nlohmann::json out = {{"output", args.options.output},
                          {"output_bytes", report->output_bytes},
                          {"payload_bytes", report->payload_bytes},
                          {"tiles_encoded", report->tiles_encoded},
                          {"tiles_copied", report->tiles_copied},
                          {"tiles_uniform", report->tiles_uniform},
                          {"tiles_empty", report->tiles_empty},
                          {"elapsed_s", report->elapsed_s},
                          {"megapixels_per_s", report->megapixels_per_s},
                          {"memory_estimate_bytes", report->memory_estimate_bytes},
                          {"memory_limit_bytes", report->memory_limit_bytes}};
    std::printf("%s\n", out.dump(2).c_str());
  } else if (!args.quiet) {
    uint64_t pixels = 0;
    for (const ImageInfo& image : report->images)
      pixels += uint64_t(image.width_px) * image.height_px;
    std::printf(
        "%s: %zu image(s), %.1f MP, %s in %.2f s (%.1f MP/s); tiles: %llu encoded, %llu "
        "uniform, %llu empty%s\n",
        args.options.output.c_str(), report->images.size(), pixels / 1e6,
        formatBytes(report->output_bytes).c_str(), report->elapsed_s, report->megapixels_per_s,
        (unsigned long long)report->tiles_encoded, (unsigned long long)report->tiles_uniform,
        (unsigned long long)report->tiles_empty,
        report->tiles_copied ? fmt::format(", {} copied as stored", report->tiles_copied).c_str()
                             : "");
  }
  return kExitOk;
}

}  // namespace

void registerBuildCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<BuildArgs>();
  CLI::App* cmd = app.add_subcommand("build",
                                     "Build an archive from TIFF/BigTIFF, PNG, JPEG, "
                                     "synthetic:WxH[:seed[:channels]], grid:COLSxROWS:PATTERN "
                                     "(files with {col} and {row}), a mosaic manifest (JSON: "
                                     "images placed on a canvas), or a pyramid to import "
                                     "(pyramidal TIFF/COG, NAME.dzi, a whole-slide image, "
                                     "openslide:PATH)");
  cmd->add_option("inputs", args->options.inputs, "Source image(s); several make a texture set");
  cmd->add_option("-o,--output", args->options.output, "Archive to write (atomically)")->required();
  cmd->add_option("--tile", args->options.tile_size_px,
                  "Tile size in pixels (power of two, 64..2048)")
      ->capture_default_str();
  cmd->add_option("--border", args->options.border_px, "Border texels per tile side (0..16)")
      ->capture_default_str();
  cmd->add_option("--codec", args->codec,
                  "raw, zstd, lz4, jpeg (or jpg), png, webp or ptm (lossless, coded against "
                  "the parent level)")
      ->capture_default_str();
  cmd->add_option("--quality", args->options.quality, "JPEG quality (1..100)")
      ->capture_default_str();
  cmd->add_option("--effort", args->options.effort,
                  "Codec effort, 0 = the codec's default: zstd level -100..22, PNG zlib level "
                  "and WebP preset 1..9, ptm mode 1..4; raw, lz4 and jpeg have none")
      ->capture_default_str();
  cmd->add_option("--chroma", args->chroma, "JPEG chroma subsampling: 420 or 444 (or 4:2:0, 4:4:4)")
      ->capture_default_str();
  cmd->add_flag("--srgb", args->options.srgb_downsample, "Average levels in linear light");
  cmd->add_option("--order", args->order, "Payload order: hilbert, quadtree or row-major")
      ->capture_default_str();
  cmd->add_option("--threads", args->options.threads,
                  fmt::format("Encoder threads, 0..{} (0 = all cores)", kMaxBuildThreads))
      ->capture_default_str();
  cmd->add_option("--memory-limit", args->memory_limit,
                  fmt::format("Most memory the build may need, e.g. 8GiB or 512M; inputs whose "
                              "claimed size needs more are refused before anything is allocated "
                              "(default: half of physical memory, here {})",
                              formatBytes(defaultBuildMemoryLimitBytes())));
  cmd->add_option("--spool-dir", args->options.spool_dir,
                  "Directory for the spool of encoded tiles, about the archive's size (default: "
                  "the output's directory)");
  cmd->add_option("--page-tiles-log2", args->options.page_tiles_log2,
                  "Directory page side as a power of two of tiles (3..8)")
      ->capture_default_str();
  cmd->add_option("--name", args->options.image_names, "Image name(s), one per input");
  cmd->add_option("--part", args->part,
                  "Build part I of N (I from 1) of a split build; join the parts with "
                  "`tessera merge` (docs/builder.md)");
  addSceneBuildOptions(*cmd);
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
