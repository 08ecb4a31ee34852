// `tessera info`: what an archive holds, for people and (with --json) for scripts.
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <tessera/archive.h>
#include <tessera/open.h>

#include "cli.h"
#include "format/metadata.h"
#include "scene_command.h"

namespace tessera::cli {

namespace {

struct LevelCounts {
  uint64_t encoded = 0, uniform = 0, procedural = 0, empty = 0, payload_bytes = 0;
  uint64_t page_bytes = 0;  ///< instance pages of the procedural tiles, shared pages each time
};

Result<LevelCounts> countLevel(const Archive& archive, uint32_t image, uint32_t level) {
  const ImageInfo& info = archive.images()[image];
  LevelCounts counts;
  for (uint32_t y = 0; y < info.tilesY(level); ++y) {
    for (uint32_t x = 0; x < info.tilesX(level); ++x) {
      TESSERA_ASSIGN_OR_RETURN(TileEntry entry, archive.tileEntry({image, level, x, y}));
      switch (entry.kind) {
        case TileKind::kEncoded:
          ++counts.encoded;
          counts.payload_bytes += entry.length_bytes;
          break;
        case TileKind::kUniform: ++counts.uniform; break;
        case TileKind::kProcedural:
          ++counts.procedural;
          counts.page_bytes += entry.length_bytes;
          break;
        default: ++counts.empty; break;
      }
    }
  }
  return counts;
}

int runInfo(const std::string& path, bool json, bool levels) {
  Result<std::shared_ptr<Archive>> opened = openArchive(path);
  if (!opened) return reportError(opened.error());
  const Archive& archive = **opened;
  // Checked at open to be one JSON object; the rest is free-form, so each field read here is
  // tested: informational ones are shown as they are, the update record is checked.
  const nlohmann::json metadata = nlohmann::json::parse(archive.metadataJson());
  const auto format_version = metadata.find("format_version");
  const nlohmann::json version_text =
      format_version == metadata.end() ? nlohmann::json("1.0") : *format_version;
  nlohmann::json out = {{"path", path},
                        {"file_bytes", archive.fileBytes()},
                        {"format_version", version_text},
                        {"images", nlohmann::json::array()}};
  if (!json)
    std::printf("%s: Tessera archive %s, %s, %zu image(s)\n", path.c_str(),
                version_text.is_string() ? version_text.get<std::string>().c_str()
                                         : version_text.dump().c_str(),
                formatBytes(archive.fileBytes()).c_str(), archive.images().size());
  // Versions appended in place (docs/update.md): recorded by `tessera update` and `append`.
  Result<detail::UpdateRecord> update = detail::parseUpdateRecord(metadata, path);
  if (!update) return reportError(update.error());
  out["version"] = update->version;
  out["dead_bytes"] = update->dead_bytes;
  if (!json && update->recorded)
    std::printf("version %llu (updated in place), %s dead (tessera compact drops them)\n",
                (unsigned long long)update->version, formatBytes(update->dead_bytes).c_str());
  const auto images_entry = metadata.find("images");
  const nlohmann::json meta_images = images_entry != metadata.end() && images_entry->is_array()
                                         ? *images_entry
                                         : nlohmann::json::array();
  for (uint32_t i = 0; i < archive.images().size(); ++i) {
    const ImageInfo& info = archive.images()[i];
    nlohmann::json image = {{"name", info.name},
                            {"width", info.width_px},
                            {"height", info.height_px},
                            {"channels", info.channels},
                            {"sample_type", sampleTypeName(info.sample_type)},
                            {"tile_size", info.tile_size_px},
                            {"border", info.border_px},
                            {"levels", info.level_count},
                            {"codec", codecName(info.default_codec)},
                            {"srgb_downsample", info.srgb_downsample}};
    if (i < meta_images.size() && meta_images[i].is_object() &&
        meta_images[i].contains("georeference"))
      image["georeference"] = meta_images[i]["georeference"];
    if (!json)
      std::printf(
          "image %u \"%s\": %ux%u px (%.1f MP), %u channel(s) of %s, %u px tiles, border %u, "
          "%u levels, codec %s\n",
          i, info.name.c_str(), info.width_px, info.height_px,
          double(info.width_px) * info.height_px / 1e6, info.channels,
          sampleTypeName(info.sample_type), info.tile_size_px, info.border_px, info.level_count,
          codecName(info.default_codec));
    if (levels) {
      nlohmann::json level_list = nlohmann::json::array();
      if (!json)
        std::printf(
            "  level        size      tiles  encoded  uniform procedural    empty    payload\n");
      for (uint32_t l = 0; l < info.level_count; ++l) {
        Result<LevelCounts> counts = countLevel(archive, i, l);
        if (!counts) return reportError(counts.error());
        level_list.push_back({{"level", l},
                              {"width", info.levelWidthPx(l)},
                              {"height", info.levelHeightPx(l)},
                              {"tiles_x", info.tilesX(l)},
                              {"tiles_y", info.tilesY(l)},
                              {"encoded", counts->encoded},
                              {"uniform", counts->uniform},
                              {"procedural", counts->procedural},
                              {"empty", counts->empty},
                              {"payload_bytes", counts->payload_bytes},
                              {"page_bytes", counts->page_bytes}});
        if (!json)
          std::printf("  %5u %11s %10s %8llu %8llu %10llu %8llu %10s\n", l,
                      fmt::format("{}x{}", info.levelWidthPx(l), info.levelHeightPx(l)).c_str(),
                      fmt::format("{}x{}", info.tilesX(l), info.tilesY(l)).c_str(),
                      (unsigned long long)counts->encoded, (unsigned long long)counts->uniform,
                      (unsigned long long)counts->procedural, (unsigned long long)counts->empty,
                      formatBytes(counts->payload_bytes).c_str());
      }
      image["level_table"] = level_list;
    }
    if (!json && image.contains("georeference"))
      std::printf("  georeference: %s\n", image["georeference"].dump().c_str());
    out["images"].push_back(image);
  }
  if (json) {
    out["metadata"] = metadata;
    std::printf("%s\n", out.dump(2).c_str());
  }
  return kExitOk;
}

}  // namespace

void registerInfoCommand(CLI::App& app, int& exit_code) {
  auto path = std::make_shared<std::string>();
  auto json = std::make_shared<bool>(false);
  auto no_levels = std::make_shared<bool>(false);
  CLI::App* cmd =
      app.add_subcommand("info", "Describe an archive: images, levels, tiles, metadata");
  cmd->add_option("archive", *path, kArchiveArgumentHelp)->required();
  cmd->add_flag("--json", *json, "Machine-readable output");
  cmd->add_flag("--no-levels", *no_levels, "Skip the per-level table (reads no directory pages)");
  addSceneInfoOptions(*cmd);
  cmd->callback([=, &exit_code] {
    if (!runSceneInfo(*path, *json, &exit_code)) exit_code = runInfo(*path, *json, !*no_levels);
  });
}

}  // namespace tessera::cli
