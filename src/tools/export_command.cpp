// `tessera export`: an archive's image as a Deep Zoom folder, PMTiles or MBTiles
// (docs/export.md).
#include <chrono>
#include <cstdio>
#include <memory>

#include <fmt/format.h>

#include <tessera/open.h>

#include "cli.h"
#include "export/export.h"

namespace tessera::cli {

namespace {

struct ExportArgs {
  std::string archive;
  std::string format;
  std::string output;
  uint32_t image = 0;
  int quality = 85;
  uint32_t leaf_entries = 0;
  bool quiet = false;
};

int runExport(const ExportArgs& args) {
  const std::optional<detail::ExportFormat> format = detail::parseExportFormat(args.format);
  if (!format) {
    std::fprintf(stderr, "tessera: export: unknown --to '%s' (accepted: %s)\n", args.format.c_str(),
                 listChoices({"dzi", "pmtiles", "mbtiles", "tiff"}).c_str());
    return kExitUsage;
  }
  Result<std::shared_ptr<Archive>> opened = openArchive(args.archive);
  if (!opened) return reportError(opened.error());
  detail::ExportOptions options;
  options.format = *format;
  options.image = args.image;
  options.jpeg_quality = args.quality;
  options.pmtiles_leaf_entries = args.leaf_entries;
  ProgressBar bar("exporting");
  const bool show_progress = !args.quiet && stderrIsTerminal();
  const auto start = std::chrono::steady_clock::now();
  if (show_progress)
    options.on_progress = [&](uint64_t done, uint64_t total) {
      const double elapsed =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      if (done % 64 == 0 || done == total)
        bar.update(double(done), double(total), elapsed, 1, "tiles/s");
    };
  Result<detail::ExportReport> report = detail::exportArchive(**opened, args.output, options);
  if (show_progress) bar.finish();
  if (!report) return reportError(report.error());
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (!args.quiet)
    std::printf(
        "%s: %llu %s tiles (%llu copied as stored, %llu of one colour encoded once per colour, "
        "the rest cut and encoded), %s in %.2f s\n",
        args.output.c_str(), static_cast<unsigned long long>(report->tiles),
        report->tile_format.c_str(), static_cast<unsigned long long>(report->tiles_copied),
        static_cast<unsigned long long>(report->tiles_uniform), formatBytes(report->bytes).c_str(),
        seconds);
  if (!args.quiet && report->georeferenced)
    std::printf("%s: the source's GeoTIFF georeference written back\n", args.output.c_str());
  // Not errors (the pixels are all there) but a difference the user must hear of.
  for (const std::string& warning : report->warnings)
    std::fprintf(stderr, "tessera export: warning: %s: %s\n", args.output.c_str(), warning.c_str());
  return kExitOk;
}

}  // namespace

void registerExportCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<ExportArgs>();
  CLI::App* cmd = app.add_subcommand(
      "export",
      "Write an image of an archive as a Deep Zoom folder, PMTiles, MBTiles or a pyramidal TIFF");
  cmd->add_option("archive", args->archive, kArchiveArgumentHelp)->required();
  cmd->add_option("--to", args->format, "Target: dzi, pmtiles, mbtiles or tiff")->required();
  cmd->add_option("output", args->output,
                  "Output file (Deep Zoom: NAME.dzi with its tiles in NAME_files beside it, or "
                  "NAME.zip holding both, as vips dzsave --container zip writes)")
      ->required();
  cmd->add_option("--image", args->image, "Which image of the archive")->capture_default_str();
  cmd->add_option("--quality", args->quality,
                  "JPEG quality of tiles that are cut or scaled rather than copied")
      ->check(CLI::Range(1, 100))
      ->capture_default_str();
  cmd->add_option("--pmtiles-leaf-entries", args->leaf_entries,
                  "PMTiles: entries per leaf directory (default: a root directory alone while "
                  "it fits in the first 16 KiB)")
      ->check(CLI::Range(1u, 1u << 20));
  cmd->add_flag("-q,--quiet", args->quiet, "Print nothing on success");
  cmd->callback([args, &exit_code] { exit_code = runExport(*args); });
}

}  // namespace tessera::cli
