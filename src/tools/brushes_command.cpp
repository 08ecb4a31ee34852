// `tessera brushes`: create a brush database, add brushes and instances, list, query and delete
// them (docs/procedural.md, "The brush database"). DB is an SQLite file or a PostGIS connection
// string (host=... dbname=... or postgresql://...).
#include <filesystem>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <tessera/brushes.h>
#include <tessera/procedural_build.h>

#include "cli.h"
#include "procedural_cli.h"

namespace tessera::cli {

namespace {

struct BrushesArgs {
  std::string database;
  std::string size;  ///< init: WxH
  std::string name;  ///< add-brush
  std::vector<std::string> images;
  std::string blend = "normal";
  std::string mask = "none";
  std::string mask_range = "0:255";
  std::vector<std::string> files;  ///< import
  uint64_t count = 0;              ///< generate
  uint64_t seed = 1;
  std::string box;            ///< query, delete
  std::vector<uint64_t> ids;  ///< delete
  uint64_t limit = 20;        ///< list
  bool json = false;
};

Result<std::unique_ptr<BrushDatabase>> openDatabase(const BrushesArgs& args, bool create = false) {
  return openBrushDatabase(args.database, create);
}

Result<BoxPx> parseBox(const std::string& text) {
  BoxPx box;
  char tail = 0;
  if (std::sscanf(text.c_str(), "%lf,%lf,%lf,%lf%c", &box.x0, &box.y0, &box.x1, &box.y1, &tail) !=
      4)
    return fail(ErrorCode::kInvalidArgument, "--box " + text + ": expected x0,y0,x1,y1");
  return box;
}

nlohmann::json instanceJson(const BrushInstance& i) {
  return {{"id", i.id},
          {"brush", i.brush},
          {"x", i.x_px},
          {"y", i.y_px},
          {"radius", i.radius_px},
          {"rotation", i.rotation_rad * 57.29577951308232},
          {"scale", i.scale},
          {"opacity", i.opacity / 255.0},
          {"tint",
           fmt::format("#{:02X}{:02X}{:02X}{:02X}", i.tint_rgba & 0xFF, (i.tint_rgba >> 8) & 0xFF,
                       (i.tint_rgba >> 16) & 0xFF, i.tint_rgba >> 24)},
          {"layer", i.layer},
          {"variant", i.variant}};
}

void printInstances(const std::vector<BrushInstance>& instances, bool json) {
  if (json) {
    nlohmann::json list = nlohmann::json::array();
    for (const BrushInstance& instance : instances) list.push_back(instanceJson(instance));
    std::printf("%s\n", nlohmann::json{{"instances", list}}.dump(2).c_str());
    return;
  }
  std::printf("%10s %6s %12s %12s %9s %8s %6s %5s\n", "id", "brush", "x", "y", "radius", "rotation",
              "layer", "opac");
  for (const BrushInstance& i : instances)
    std::printf("%10llu %6u %12.2f %12.2f %9.2f %8.1f %6d %5u\n", (unsigned long long)i.id, i.brush,
                i.x_px, i.y_px, i.radius_px, i.rotation_rad * 57.29577951308232, i.layer,
                i.opacity);
}

int runInit(const BrushesArgs& args) {
  TextureExtent extent;
  char tail = 0;
  if (std::sscanf(args.size.c_str(), "%ux%u%c", &extent.width_px, &extent.height_px, &tail) != 2 ||
      extent.width_px == 0 || extent.height_px == 0)
    return reportError({ErrorCode::kInvalidArgument, "--size " + args.size + ": expected WxH"});
  auto db = openDatabase(args, true);
  if (!db) return reportError(db.error());
  if (auto set = (*db)->setTextureExtent(extent); !set) return reportError(set.error());
  std::printf("%s: %s brush database, texture %ux%u\n", args.database.c_str(), (*db)->backend(),
              extent.width_px, extent.height_px);
  return kExitOk;
}

int runAddBrush(const BrushesArgs& args) {
  Brush brush;
  brush.name = args.name;
  if (!parseBlendModeName(args.blend, &brush.blend))
    return reportError({ErrorCode::kInvalidArgument, "unknown blend mode " + args.blend});
  if (!parseMaskSourceName(args.mask, &brush.mask))
    return reportError({ErrorCode::kInvalidArgument, "unknown mask source " + args.mask});
  unsigned low = 0, high = 0;
  char tail = 0;
  if (std::sscanf(args.mask_range.c_str(), "%u:%u%c", &low, &high, &tail) != 2 || low > 255 ||
      high > 255)
    return reportError({ErrorCode::kInvalidArgument,
                        "--mask-range " + args.mask_range + ": expected LOW:HIGH in 0..255"});
  brush.mask_low = uint8_t(low);
  brush.mask_high = uint8_t(high);
  const std::string scratch = std::filesystem::temp_directory_path().string();
  for (const std::string& path : args.images) {
    Result<Image> image = readImageRgba(path, scratch);
    if (!image) return reportError(image.error());
    brush.images.push_back(std::move(*image));
  }
  auto db = openDatabase(args);
  if (!db) return reportError(db.error());
  Result<uint32_t> id = (*db)->addBrush(brush);
  if (!id) return reportError(id.error());
  std::printf("brush %u: %s (%s, %zu image(s))\n", *id, brush.name.c_str(),
              blendModeName(brush.blend), brush.images.size());
  return kExitOk;
}

int runImport(const BrushesArgs& args) {
  auto db = openDatabase(args);
  if (!db) return reportError(db.error());
  for (const std::string& file : args.files) {
    Result<ImportReport> report = importInstances(**db, file);
    if (!report) return reportError(report.error());
    std::printf("%s: %llu instances (ids %llu..%llu)\n", file.c_str(),
                (unsigned long long)report->instances, (unsigned long long)report->first_id,
                (unsigned long long)report->last_id);
  }
  return kExitOk;
}

int runGenerate(const BrushesArgs& args) {
  auto db = openDatabase(args);
  if (!db) return reportError(db.error());
  Result<TextureExtent> extent = (*db)->textureExtent();
  Result<std::vector<Brush>> brushes = (*db)->brushes();
  if (!extent) return reportError(extent.error());
  if (!brushes) return reportError(brushes.error());
  if (extent->width_px == 0 || brushes->empty())
    return reportError({ErrorCode::kInvalidArgument,
                        args.database + ": set the texture size and add brushes first"});
  // In batches, each its own transaction, so that 10^7 instances need no 10^7-element vector.
  constexpr uint64_t kBatch = 1000000;
  std::vector<BrushInstance> all =
      generateInstances(args.count, *extent, uint32_t(brushes->size()), args.seed);
  for (uint64_t first = 0; first < all.size(); first += kBatch) {
    const uint64_t n = std::min<uint64_t>(kBatch, all.size() - first);
    auto ids = (*db)->addInstances({all.data() + first, n});
    if (!ids) return reportError(ids.error());
  }
  std::printf("%s: %llu instances generated (seed %llu)\n", args.database.c_str(),
              (unsigned long long)all.size(), (unsigned long long)args.seed);
  return kExitOk;
}

int runList(const BrushesArgs& args) {
  auto db = openDatabase(args);
  if (!db) return reportError(db.error());
  Result<std::vector<Brush>> brushes = (*db)->brushes();
  Result<uint64_t> count = (*db)->instanceCount();
  Result<TextureExtent> extent = (*db)->textureExtent();
  if (!brushes || !count || !extent)
    return reportError(!brushes ? brushes.error() : !count ? count.error() : extent.error());
  std::vector<BrushInstance> first;
  Result<void> listed = (*db)->forEachInstance([&](const BrushInstance& instance) {
    first.push_back(instance);
    return first.size() < args.limit;
  });
  if (!listed) return reportError(listed.error());
  if (!args.json) {
    std::printf("%s: %s, texture %ux%u, %zu brush(es), %llu instance(s)\n", args.database.c_str(),
                (*db)->backend(), extent->width_px, extent->height_px, brushes->size(),
                (unsigned long long)*count);
    for (size_t b = 0; b < brushes->size(); ++b)
      std::printf("  brush %zu: %s, %s, mask %s %u:%u, %zu image(s)\n", b,
                  (*brushes)[b].name.c_str(), blendModeName((*brushes)[b].blend),
                  maskSourceName((*brushes)[b].mask), (*brushes)[b].mask_low,
                  (*brushes)[b].mask_high, (*brushes)[b].images.size());
  }
  printInstances(first, args.json);
  return kExitOk;
}

int runQuery(const BrushesArgs& args) {
  Result<BoxPx> box = parseBox(args.box);
  if (!box) return reportError(box.error());
  auto db = openDatabase(args);
  if (!db) return reportError(db.error());
  std::vector<BrushInstance> found;
  if (auto queried = (*db)->query(*box, found); !queried) return reportError(queried.error());
  printInstances(found, args.json);
  return kExitOk;
}

int runDelete(const BrushesArgs& args) {
  auto db = openDatabase(args);
  if (!db) return reportError(db.error());
  uint64_t deleted = 0;
  if (!args.box.empty()) {
    Result<BoxPx> box = parseBox(args.box);
    if (!box) return reportError(box.error());
    Result<uint64_t> in_box = (*db)->deleteInstancesIn(*box);
    if (!in_box) return reportError(in_box.error());
    deleted += *in_box;
  }
  if (!args.ids.empty()) {
    Result<uint64_t> by_id = (*db)->deleteInstances(args.ids);
    if (!by_id) return reportError(by_id.error());
    deleted += *by_id;
  }
  std::printf("%llu instance(s) deleted\n", (unsigned long long)deleted);
  return kExitOk;
}

CLI::App* brushesSubcommand(CLI::App* parent, const char* name, const char* help,
                            const std::shared_ptr<BrushesArgs>& args) {
  CLI::App* cmd = parent->add_subcommand(name, help);
  cmd->add_option("database", args->database, "SQLite file or PostGIS connection string")
      ->required();
  return cmd;
}

}  // namespace

void registerBrushesCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<BrushesArgs>();
  CLI::App* brushes = app.add_subcommand("brushes", "Edit a brush database (procedural tiles)");
  brushes->require_subcommand(1);
  CLI::App* init =
      brushesSubcommand(brushes, "init", "Create a database for a texture of a size", args);
  init->add_option("--size", args->size, "Texture size WxH in level-0 texels")->required();
  init->callback([args, &exit_code] { exit_code = runInit(*args); });
  CLI::App* add_brush =
      brushesSubcommand(brushes, "add-brush", "Add a brush from RGBA image(s)", args);
  add_brush->add_option("--name", args->name, "Unique name")->required();
  add_brush->add_option("--image", args->images, "Image(s) (PNG, TIFF, JPEG), one per variant")
      ->required();
  add_brush->add_option("--blend", args->blend, "normal, multiply, add or overlay")
      ->capture_default_str();
  add_brush->add_option("--mask", args->mask, "none, height or slope")->capture_default_str();
  add_brush
      ->add_option("--mask-range", args->mask_range,
                   "LOW:HIGH layer values where the mask ramps from 0 to full")
      ->capture_default_str();
  add_brush->callback([args, &exit_code] { exit_code = runAddBrush(*args); });
  CLI::App* add =
      brushesSubcommand(brushes, "add", "Import instances from .csv, .json or .geojson", args);
  add->add_option("files", args->files, "Instance files; each is one transaction")->required();
  add->callback([args, &exit_code] { exit_code = runImport(*args); });
  CLI::App* generate =
      brushesSubcommand(brushes, "generate", "Add a deterministic test instance set", args);
  generate->add_option("--count", args->count, "Instances")->required();
  generate->add_option("--seed", args->seed, "Seed")->capture_default_str();
  generate->callback([args, &exit_code] { exit_code = runGenerate(*args); });
  CLI::App* list =
      brushesSubcommand(brushes, "list", "Brushes, counts and the first instances", args);
  list->add_option("--limit", args->limit, "Instances to show")->capture_default_str();
  list->add_flag("--json", args->json, "Instances as JSON");
  list->callback([args, &exit_code] { exit_code = runList(*args); });
  CLI::App* query = brushesSubcommand(brushes, "query", "Instances whose bounds meet a box", args);
  query->add_option("--box", args->box, "x0,y0,x1,y1 in level-0 texels")->required();
  query->add_flag("--json", args->json, "As JSON");
  query->callback([args, &exit_code] { exit_code = runQuery(*args); });
  CLI::App* remove = brushesSubcommand(brushes, "delete", "Delete instances by id or by box", args);
  remove->add_option("--id", args->ids, "Instance id(s)");
  remove->add_option("--box", args->box, "x0,y0,x1,y1: every instance meeting it");
  remove->callback([args, &exit_code] {
    exit_code = args->ids.empty() && args->box.empty()
                    ? reportError({ErrorCode::kInvalidArgument, "delete: give --id or --box"})
                    : runDelete(*args);
  });
}

}  // namespace tessera::cli
