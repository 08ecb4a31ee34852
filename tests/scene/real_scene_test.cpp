// Real scene data nobody here made: the FlightGear models of Debian's flightgear-data-models
// (GPL-2+, about 144 MB to download, 274 MB unpacked), fetched at test time with apt-get
// download + dpkg-deb -x into the build folder (kept there for later runs), never committed.
// The test places every model whose textures are PNG or JPEG (the SGI .rgb ones are not read)
// twice in a .stg placement list around San Francisco and builds it: hundreds of textured
// objects and about two hundred textures shared between models and placements.
// Set TESSERA_FGDATA to an unpacked Models folder to skip the download, and TESSERA_KEEP_SCENE
// to a path to keep a copy of the archive built (bench/scene_texel_memory.sh flies it).
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>

#include <gtest/gtest.h>

#include <tessera/archive.h>
#include <tessera/scene.h>
#include <tessera/scene_build.h>

#include "builder/texture_pyramid.h"
#include "importers.h"
#include "scene/scene_test_support.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;

// The unpacked Models folder, fetching the package when needed; empty when it cannot be had.
std::string flightGearModels(std::string* why) {
  if (const char* given = std::getenv("TESSERA_FGDATA")) return given;
  const fs::path cache = fs::path(TESSERA_BINARY_DIR) / "scene-data" / "flightgear-data-models";
  const fs::path models = cache / "usr/share/games/flightgear/Models";
  if (fs::is_directory(models)) return models.string();
  fs::create_directories(cache);
  const std::string command = "cd '" + cache.string() +
                              "' && apt-get download flightgear-data-models >fetch.log 2>&1 && "
                              "dpkg-deb -x flightgear-data-models_*.deb . && "
                              "rm -f flightgear-data-models_*.deb";
  if (std::system(command.c_str()) != 0 || !fs::is_directory(models)) {
    *why = "cannot fetch Debian's flightgear-data-models (offline?); see " +
           (cache / "fetch.log").string();
    return "";
  }
  return models.string();
}

// Models whose every texture is a PNG or JPEG our readers decode, and which Assimp reads.
std::vector<std::string> usableModels(const std::string& root) {
  std::vector<std::string> out;
  std::vector<fs::path> files;
  for (const auto& entry : fs::recursive_directory_iterator(root))
    if (entry.path().extension() == ".ac") files.push_back(entry.path());
  std::sort(files.begin(), files.end());
  for (const fs::path& file : files) {
    std::ifstream in(file);
    std::string line;
    bool ok = true, any = false;
    while (ok && std::getline(in, line)) {
      // AC3D: texture "name.png" (std::regex trips GCC 12's -Wmaybe-uninitialized under ASan).
      const std::string prefix = "texture \"";
      const size_t end = line.find('"', prefix.size());
      if (line.rfind(prefix, 0) != 0 || end == std::string::npos) continue;
      any = true;
      const fs::path texture = file.parent_path() / line.substr(prefix.size(), end - prefix.size());
      const std::string ext = texture.extension().string();
      ok = (ext == ".png" || ext == ".jpg") &&
           detail::readImageFile(texture.string(), 4096).has_value();
    }
    if (!ok || !any) continue;
    if (detail::importAssimp(file.string()).has_value()) out.push_back(file.string());
  }
  return out;
}

TEST(RealScene, FlightGearModelsPlacedAroundSanFranciscoBuildAndRead) {
  std::string why;
  const std::string models = flightGearModels(&why);
  if (models.empty()) GTEST_SKIP() << why;
  const std::vector<std::string> usable = usableModels(models);
  ASSERT_GT(usable.size(), 100u) << "fewer usable models than expected in " << models;
  test::ScratchDir dir;
  // The same placements are kept beside the fetched package (scene-data/sf.stg) for the
  // coverage hints benchmark (docs/scenes.md, "Coverage hints"), which builds them itself.
  const fs::path kept_dir = fs::path(TESSERA_BINARY_DIR) / "scene-data";
  for (const fs::path& folder : {fs::path(dir.path()), kept_dir}) {
    std::ofstream stg(folder / "sf.stg");
    for (size_t k = 0; k < 2 * usable.size(); ++k) {
      const double lon = -122.40 + 0.004 * double(k % 30), lat = 37.62 + 0.004 * double(k / 30);
      stg << "OBJECT_STATIC " << fs::relative(usable[k % usable.size()], folder).string() << " "
          << lon << " " << lat << " " << 5.0 + k % 7 << " " << (k * 37) % 360 << "\n";
    }
  }
  SceneBuildOptions options;
  options.input = dir.file("sf.stg");
  options.output = dir.file("sf.tess");
  options.tile_size_px = 128;
  options.threads = 2;
  options.coverage_hints = true;
  options.hint_resolution_px = 32;
  Result<SceneBuildReport> report = buildScene(options);
  ASSERT_TRUE(report.has_value()) << report.error().message;
  std::printf(
      "FlightGear scene: %zu models placed twice, %u objects, %u meshes, %u textures, "
      "%u nodes (depth %u), %llu bytes in %.1f s; %llu leaf copies, %llu copies avoided; "
      "geometry %llu bytes (%llu raw); coverage hints: %llu cells, %llu entries, %llu bytes in "
      "%.1f s\n",
      usable.size(), report->summary.objects, report->summary.meshes, report->summary.textures,
      report->summary.nodes, report->summary.tree_depth, (unsigned long long)report->output_bytes,
      report->elapsed_s, (unsigned long long)report->promotion.leaf_copies,
      (unsigned long long)report->promotion.copies_avoided,
      (unsigned long long)report->geometry_stored_bytes,
      (unsigned long long)report->geometry_raw_bytes, (unsigned long long)report->hint_cells,
      (unsigned long long)report->hint_entries, (unsigned long long)report->hint_bytes,
      report->hint_seconds);
  // bench/scene_texel_memory.sh flies this scene: it asks for a copy of the archive.
  if (const char* keep = std::getenv("TESSERA_KEEP_SCENE"))
    fs::copy_file(options.output, keep, fs::copy_options::overwrite_existing);
  EXPECT_GE(report->summary.objects, 300u);
  EXPECT_GE(report->summary.textures, 100u);
  EXPECT_GT(report->promotion.copies_avoided, 0u) << "placements share textures";
  EXPECT_GT(report->hint_entries, report->hint_cells) << "cells see several textures each";

  auto scene = SceneArchive::openFile(options.output);
  ASSERT_TRUE(scene.has_value()) << scene.error().message;
  auto nodes = (*scene)->allNodes();
  ASSERT_TRUE(nodes.has_value()) << nodes.error().message;
  for (const SceneNode& node : *nodes) {
    auto contents = (*scene)->readNode(node);
    ASSERT_TRUE(contents.has_value()) << contents.error().message;
    for (const SceneMesh& mesh : contents->meshes)
      ASSERT_TRUE((*scene)->readMesh(mesh).has_value());
  }
  auto archive = Archive::openFile(options.output);
  ASSERT_TRUE(archive.has_value()) << archive.error().message;
  EXPECT_TRUE((*archive)->verify(true).ok());
  const SceneVerifyReport walked = verifyScene(**scene, (*archive)->images(), false);
  EXPECT_TRUE(walked.ok()) << (walked.faults.empty() ? "" : walked.faults[0]);
  EXPECT_EQ(walked.hint_cells_checked, report->hint_cells);
}

}  // namespace
}  // namespace tessera
