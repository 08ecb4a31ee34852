// The cold-load benchmark's scene: the FlightGear models of Debian's flightgear-data-models that
// the real-data test builds (tests/scene/real_scene_test.cpp: every model whose textures are
// PNG or JPEG our readers decode and which Assimp reads, placed twice on a grid around San
// Francisco), kept as the separate .ac and image files a viewer would load, beside the scene
// archive built from them.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include <fmt/format.h>

#include <tessera/scene_build.h>

#include "builder/texture_pyramid.h"
#include "importers.h"
#include "scene_coldload.h"

namespace coldload {
namespace fs = std::filesystem;
using tessera::ErrorCode;
using tessera::fail;
using tessera::Result;

namespace {

// The texture files an AC3D model names (its `texture "file"` lines), beside the model.
std::vector<fs::path> acTextures(const fs::path& model) {
  std::vector<fs::path> out;
  std::ifstream in(model);
  std::string line;
  const std::string prefix = "texture \"";
  while (std::getline(in, line)) {
    const size_t end = line.find('"', prefix.size());
    if (line.rfind(prefix, 0) != 0 || end == std::string::npos) continue;
    out.push_back(model.parent_path() / line.substr(prefix.size(), end - prefix.size()));
  }
  return out;
}

// Models wider than this are not buildings or vehicles but the sky: Astro/ and Weather/ hold
// the planet and cloud layers, thousands of kilometres across, which contain every camera and
// so want their full resolution in every view of a city.
constexpr double kMaxModelSideM = 2000;

double largestSide(const tessera::detail::ImportedScene& model) {
  double side = 0;
  for (const tessera::detail::ImportedObject& object : model.objects) {
    for (int axis = 0; axis < 3; ++axis)
      side = std::max(side, double(object.bounds.max[axis]) - object.bounds.min[axis]);
  }
  return side;
}

struct UsableModel {
  fs::path path;
  uint32_t objects = 0;  ///< what the importer makes of one placement
  std::vector<fs::path> textures;
};

// Models with at least one texture, every texture a PNG or JPEG the builder decodes, that
// Assimp reads: the real-data test's selection, in path order.
std::vector<UsableModel> usableModels(const fs::path& root) {
  std::vector<fs::path> files;
  for (const auto& entry : fs::recursive_directory_iterator(root))
    if (entry.path().extension() == ".ac") files.push_back(entry.path());
  std::sort(files.begin(), files.end());
  std::vector<UsableModel> out;
  std::map<fs::path, bool> decodable;
  for (const fs::path& file : files) {
    UsableModel model{file, 0, acTextures(file)};
    bool ok = !model.textures.empty();
    for (const fs::path& texture : model.textures) {
      auto known = decodable.find(texture);
      if (known == decodable.end()) {
        const std::string ext = texture.extension().string();
        const bool readable = (ext == ".png" || ext == ".jpg") &&
                              tessera::detail::readImageFile(texture.string(), 4096).has_value();
        known = decodable.emplace(texture, readable).first;
      }
      ok = ok && known->second;
    }
    if (!ok) continue;
    Result<tessera::detail::ImportedScene> imported = tessera::detail::importAssimp(file.string());
    if (!imported || !tessera::detail::validateScene(*imported).has_value()) continue;
    if (largestSide(*imported) > kMaxModelSideM) continue;
    model.objects = uint32_t(imported->objects.size());
    out.push_back(std::move(model));
  }
  return out;
}

}  // namespace

Result<void> prepare(const std::string& models_dir, const std::string& work_dir) {
  const fs::path work(work_dir), models(models_dir);
  fs::create_directories(work);
  std::error_code ec;
  fs::remove(work / "Models", ec);
  fs::create_directory_symlink(fs::absolute(models), work / "Models", ec);
  if (ec)
    return fail(ErrorCode::kIo, fmt::format("{}: cannot link Models: {}", work_dir, ec.message()));
  const std::vector<UsableModel> usable = usableModels(models);
  if (usable.size() < 100) {  // the test finds 219 (with the sky)
    return fail(ErrorCode::kNotFound,
                fmt::format("{}: only {} usable models", models_dir, usable.size()));
  }
  std::ofstream stg(work / "sf.stg"), table(work / "placements.tsv"), list(work / "files.txt");
  std::set<fs::path> files;
  uint32_t first_object = 0;
  // Two placements of every model on a 30-column grid 0.004 degrees apart, as the test does.
  for (size_t k = 0; k < 2 * usable.size(); ++k) {
    const UsableModel& model = usable[k % usable.size()];
    const double lon = -122.40 + 0.004 * double(k % 30), lat = 37.62 + 0.004 * double(k / 30);
    const std::string relative = "Models" / fs::relative(model.path, models);
    stg << "OBJECT_STATIC " << relative << " " << lon << " " << lat << " " << 5.0 + k % 7 << " "
        << (k * 37) % 360 << "\n";
    table << k + 1 << "\t" << relative << "\t" << first_object << "\t" << model.objects << "\n";
    first_object += model.objects;
    files.insert(model.path);
    files.insert(model.textures.begin(), model.textures.end());
  }
  for (const fs::path& file : files) list << fs::absolute(file).string() << "\n";
  stg.close();
  table.close();
  list.close();
  std::printf("prepare: %zu usable models, %zu placements, %u objects, %zu files\n", usable.size(),
              2 * usable.size(), first_object, files.size());

  tessera::SceneBuildOptions options;
  options.input = (work / "sf.stg").string();
  options.output = (work / "sf.tess").string();
  options.tile_size_px = 128;
  options.threads = 2;
  TESSERA_ASSIGN_OR_RETURN(tessera::SceneBuildReport report, tessera::buildScene(options));
  if (report.summary.objects != first_object) {
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: {} objects built, {} expected from the placements", options.output,
                            report.summary.objects, first_object));
  }
  std::printf("prepare: %s: %u objects, %u textures, %u nodes, %llu bytes in %.1f s\n",
              options.output.c_str(), report.summary.objects, report.summary.textures,
              report.summary.nodes, (unsigned long long)report.output_bytes, report.elapsed_s);
  return {};
}

Result<std::vector<Placement>> readPlacements(const std::string& path) {
  std::ifstream in(path);
  if (!in) return fail(ErrorCode::kNotFound, path + ": cannot open (run prepare)");
  std::vector<Placement> out;
  std::string text;
  while (std::getline(in, text)) {
    std::istringstream fields(text);
    Placement p;
    if (!(fields >> p.line >> p.model >> p.first_object >> p.object_count)) {
      return fail(ErrorCode::kCorrupt, fmt::format("{}: bad line '{}'", path, text));
    }
    out.push_back(std::move(p));
  }
  return out;
}

}  // namespace coldload
