// `tessera update`, `append` and `compact`: an archive changed in place by appended versions,
// and rewritten without their dead bytes (docs/update.md).
#include <chrono>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <tessera/archive.h>

#include "builder/texture_pyramid.h"
#include "cli.h"
#include "update/archive_update.h"

namespace tessera::cli {

namespace {

/// Patches are held in memory whole; 16384 px a side is 1 GiB of RGBA at most.
constexpr uint32_t kMaxPatchSidePx = 16384;

using Clock = std::chrono::steady_clock;

bool parsePosition(const std::string& text, uint32_t& x, uint32_t& y) {
  const size_t comma = text.find(',');
  if (comma == std::string::npos || comma == 0 || comma + 1 == text.size()) return false;
  auto digits = [](const std::string& s) {
    return s.size() <= 9 && s.find_first_not_of("0123456789") == std::string::npos;
  };
  const std::string left = text.substr(0, comma), right = text.substr(comma + 1);
  if (!digits(left) || !digits(right)) return false;
  x = uint32_t(std::stoul(left));
  y = uint32_t(std::stoul(right));
  return true;
}

void printReport(const char* what, const std::string& path, const detail::UpdateReport& report,
                 double elapsed_s, bool json) {
  if (json) {
    std::printf("%s\n", nlohmann::json({{"path", path},
                                        {"version", report.version},
                                        {"bytes_written", report.bytes_written},
                                        {"tiles_rewritten", report.tiles_rewritten},
                                        {"dead_bytes", report.dead_bytes},
                                        {"file_bytes", report.file_bytes},
                                        {"elapsed_s", elapsed_s}})
                            .dump(2)
                            .c_str());
    return;
  }
  std::printf("%s: %s, version %llu: %llu tiles, %s written in %.1f ms; %s dead of %s\n",
              path.c_str(), what, (unsigned long long)report.version,
              (unsigned long long)report.tiles_rewritten, formatBytes(report.bytes_written).c_str(),
              elapsed_s * 1e3, formatBytes(report.dead_bytes).c_str(),
              formatBytes(report.file_bytes).c_str());
}

struct UpdateArgs {
  std::string archive, patch, at;
  uint32_t image = 0;
  bool json = false;
};

int runUpdate(const UpdateArgs& args) {
  uint32_t x = 0, y = 0;
  if (!parsePosition(args.at, x, y)) {
    std::fprintf(stderr, "tessera: --at %s: expected X,Y in level-0 pixels (e.g. 512,1024)\n",
                 args.at.c_str());
    return kExitUsage;
  }
  const auto start = Clock::now();
  Result<Image> patch = detail::readImageFile(args.patch, kMaxPatchSidePx);
  if (!patch) return reportError(patch.error());
  Result<detail::UpdateReport> report =
      detail::updateRegion(args.archive, args.image, x, y, *patch, args.patch);
  if (!report) return reportError(report.error());
  printReport("updated", args.archive, *report,
              std::chrono::duration<double>(Clock::now() - start).count(), args.json);
  return kExitOk;
}

struct AppendArgs {
  std::string archive, input, codec, name;
  uint32_t tile = 0, border = 0;
  int quality = 85;
  bool json = false;
};

int runAppend(AppendArgs args, bool border_given) {
  Result<std::shared_ptr<Archive>> archive = Archive::openFile(args.archive);
  if (!archive) return reportError(archive.error());
  // Unset options follow the archive's first image, so a texture set stays uniform.
  const ImageInfo& first = (*archive)->images()[0];
  BuildOptions options;
  options.inputs = {args.input};
  options.tile_size_px = args.tile ? args.tile : first.tile_size_px;
  options.border_px = border_given ? args.border : first.border_px;
  options.codec = first.default_codec;
  options.page_tiles_log2 = first.page_tiles_log2;
  options.srgb_downsample = first.srgb_downsample;
  options.quality = args.quality;
  if (!args.codec.empty() && !parseCodecName(args.codec, &options.codec)) {
    std::fprintf(stderr, "tessera: --codec %s: unknown codec\n", args.codec.c_str());
    return kExitUsage;
  }
  if (!args.name.empty()) options.image_names = {args.name};
  archive->reset();
  const auto start = Clock::now();
  Result<detail::UpdateReport> report = detail::appendImage(args.archive, options);
  if (!report) return reportError(report.error());
  printReport("appended an image", args.archive, *report,
              std::chrono::duration<double>(Clock::now() - start).count(), args.json);
  return kExitOk;
}

int runCompact(const std::string& path, const std::string& output) {
  Result<detail::CompactReport> report =
      detail::compactArchive(path, output.empty() ? path : output);
  if (!report) return reportError(report.error());
  std::printf("%s: compacted into %s: %s -> %s\n", path.c_str(),
              (output.empty() ? path : output).c_str(), formatBytes(report->bytes_before).c_str(),
              formatBytes(report->bytes_after).c_str());
  return kExitOk;
}

}  // namespace

void registerUpdateCommands(CLI::App& app, int& exit_code) {
  auto update = std::make_shared<UpdateArgs>();
  CLI::App* cmd = app.add_subcommand(
      "update", "Replace a region of an image's full resolution in place (docs/update.md)");
  cmd->add_option("archive", update->archive, "Archive file to change")->required();
  cmd->add_option("patch", update->patch, "Image with the new texels (TIFF, PNG, JPEG)")
      ->required();
  cmd->add_option("--image", update->image, "Image index, from 0")->capture_default_str();
  cmd->add_option("--at", update->at, "X,Y of the patch's top-left texel at level 0")->required();
  cmd->add_flag("--json", update->json, "Print the report as JSON");
  cmd->callback([update, &exit_code] { exit_code = runUpdate(*update); });

  auto append = std::make_shared<AppendArgs>();
  CLI::App* add = app.add_subcommand("append", "Add an image to an archive in place");
  add->add_option("archive", append->archive, "Archive file to change")->required();
  add->add_option("image", append->input, "Image to add (TIFF, PNG, JPEG, synthetic:...)")
      ->required();
  add->add_option("--tile", append->tile, "Tile side in pixels (default: the first image's)");
  CLI::Option* border =
      add->add_option("--border", append->border, "Border texels (default: the first image's)");
  add->add_option("--codec", append->codec, "Codec (default: the first image's)");
  add->add_option("--quality", append->quality, "JPEG quality (1..100)")->capture_default_str();
  add->add_option("--name", append->name, "Image name stored in the metadata");
  add->add_flag("--json", append->json, "Print the report as JSON");
  add->callback(
      [append, border, &exit_code] { exit_code = runAppend(*append, border->count() > 0); });

  auto compact = std::make_shared<std::pair<std::string, std::string>>();
  CLI::App* cmp =
      app.add_subcommand("compact", "Rewrite an archive without the bytes updates left dead");
  cmp->add_option("archive", compact->first, "Archive file")->required();
  cmp->add_option("-o,--output", compact->second, "Output (default: replace the archive)");
  cmp->callback([compact, &exit_code] { exit_code = runCompact(compact->first, compact->second); });
}

}  // namespace tessera::cli
