// FlightGear placement lists (.stg): each OBJECT_SHARED or OBJECT_STATIC line places a model at
// a longitude, latitude, elevation (m) and heading (degrees). Models are read once each through
// Assimp and placed as instances, so their meshes and textures are shared between placements:
// the sharing that seed 004's promotion exists for.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include <fmt/format.h>

#include "assimp_model.h"
#include "importers.h"

namespace tessera::detail {

namespace {

struct Placement {
  std::string model;  ///< resolved path
  double lon_deg = 0, lat_deg = 0, elevation_m = 0, heading_deg = 0;
  uint32_t line = 0;
};

// OBJECT_SHARED paths are relative to the FlightGear data root; here, to the first of the
// .stg's folder and its ancestors where the file exists. OBJECT_STATIC paths are relative to
// the .stg's folder.
std::string resolveModel(const std::filesystem::path& stg_dir, const std::string& reference,
                         bool shared) {
  if (!shared) return (stg_dir / reference).lexically_normal().string();
  std::error_code ec;
  for (std::filesystem::path dir = stg_dir;; dir = dir.parent_path()) {
    std::filesystem::path candidate = (dir / reference).lexically_normal();
    if (std::filesystem::exists(candidate, ec)) return candidate.string();
    if (dir == dir.parent_path() || dir.empty()) break;
  }
  return (stg_dir / reference).lexically_normal().string();
}

Result<std::vector<Placement>> parseStg(const std::string& path) {
  TESSERA_TRY(requireRegularFile(path));
  std::ifstream in(path);
  if (!in) return fail(ErrorCode::kNotFound, path + ": cannot open");
  const std::filesystem::path dir = std::filesystem::path(path).parent_path();
  std::vector<Placement> out;
  std::string text;
  for (uint32_t line = 1; std::getline(in, text); ++line) {
    std::istringstream fields(text);
    std::string keyword, model;
    if (!(fields >> keyword) || keyword[0] == '#') continue;
    if (keyword != "OBJECT_SHARED" && keyword != "OBJECT_STATIC") continue;
    Placement p;
    p.line = line;
    if (!(fields >> model >> p.lon_deg >> p.lat_deg >> p.elevation_m >> p.heading_deg) ||
        !std::isfinite(p.lon_deg) || !std::isfinite(p.lat_deg) || !std::isfinite(p.elevation_m) ||
        !std::isfinite(p.heading_deg) || std::abs(p.lat_deg) > 90 || std::abs(p.lon_deg) > 360)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: line {}: expected MODEL LON LAT ELEV HDG", path, line));
    p.model = resolveModel(dir, model, keyword == "OBJECT_SHARED");
    out.push_back(std::move(p));
  }
  if (out.empty()) return fail(ErrorCode::kInvalidArgument, path + ": no object placements");
  return out;
}

}  // namespace

Result<ImportedScene> importStg(const std::string& path) {
  TESSERA_ASSIGN_OR_RETURN(std::vector<Placement> placements, parseStg(path));
  ImportedScene scene;
  scene.source = path;
  scene.importer = "stg";
  TextureIndex textures;
  std::map<std::string, ModelTemplate> models;
  // A local tangent plane at the first placement: x east, y up, z south (glTF's y-up).
  const Placement& origin = placements[0];
  constexpr double kPi = 3.14159265358979323846;
  const double metres_per_lon = 111319.49 * std::cos(origin.lat_deg * kPi / 180);
  constexpr double kMetresPerLat = 110574.0;
  for (const Placement& p : placements) {
    auto it = models.find(p.model);
    if (it == models.end()) {
      Result<ModelTemplate> model = loadAssimpModel(p.model, scene, textures);
      if (!model)
        return fail(model.error().code,
                    fmt::format("{}: line {}: {}", path, p.line, model.error().message));
      it = models.emplace(p.model, std::move(*model)).first;
    }
    const double h = p.heading_deg * kPi / 180;
    const float c = float(std::cos(h)), s = float(std::sin(h));
    const std::array<float, 12> place = {
        c,  0, s, float((p.lon_deg - origin.lon_deg) * metres_per_lon),
        0,  1, 0, float(p.elevation_m - origin.elevation_m),
        -s, 0, c, float(-(p.lat_deg - origin.lat_deg) * kMetresPerLat)};
    for (ImportedObject object : it->second.objects) {
      object.transform = composeTransforms(place, object.transform);
      scene.objects.push_back(object);
    }
  }
  return scene;
}

}  // namespace tessera::detail
