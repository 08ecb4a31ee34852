// Scene archives in `tessera build` and `tessera info`.
#include "scene_command.h"

#include <algorithm>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <tessera/open.h>
#include <tessera/scene.h>
#include <tessera/scene_build.h>

#include "cli.h"

namespace tessera::cli {

namespace {

struct SceneCliOptions {
  uint32_t leaf_capacity = 16;
  uint32_t max_children = 8;
  std::string geometry_codec = "meshopt";
  std::vector<std::string> texture_sources;
  uint32_t max_texture_side_px = 16384;
  uint32_t tree_depth = 2;
  bool coverage_hints = false;
  double hint_cell_size = 0;
  uint32_t hint_resolution_px = 64;
};

SceneCliOptions& sceneCliOptions() {
  static SceneCliOptions options;
  return options;
}

void printSceneReport(const SceneBuildReport& r, const std::string& output, bool json) {
  const PromotionStats& p = r.promotion;
  if (json) {
    nlohmann::json out = {{"output", output},
                          {"output_bytes", r.output_bytes},
                          {"importer", r.importer},
                          {"objects", r.summary.objects},
                          {"meshes", r.summary.meshes},
                          {"textures", r.summary.textures},
                          {"nodes", r.summary.nodes},
                          {"tree_depth", r.summary.tree_depth},
                          {"texture_payload_bytes", r.texture_payload_bytes},
                          {"geometry_raw_bytes", r.geometry_raw_bytes},
                          {"geometry_stored_bytes", r.geometry_stored_bytes},
                          {"tiles_encoded", r.tiles_encoded},
                          {"copies_avoided", p.copies_avoided},
                          {"leaf_copies", p.leaf_copies},
                          {"stored_at_depth", p.stored_at_depth},
                          {"hint_cells", r.hint_cells},
                          {"hint_entries", r.hint_entries},
                          {"hint_bytes", r.hint_bytes},
                          {"hint_seconds", r.hint_seconds},
                          {"elapsed_s", r.elapsed_s}};
    std::printf("%s\n", out.dump(2).c_str());
    return;
  }
  std::printf(
      "%s: scene (%s) of %u objects, %u meshes, %u textures; R-tree of %u nodes, depth %u; "
      "%s in %.2f s\n",
      output.c_str(), r.importer.c_str(), r.summary.objects, r.summary.meshes, r.summary.textures,
      r.summary.nodes, r.summary.tree_depth, formatBytes(r.output_bytes).c_str(), r.elapsed_s);
  std::printf(
      "  textures %s in %llu tiles; geometry %s (%s raw); promotion: %llu leaf copies -> %llu "
      "stored, %llu copies avoided\n",
      formatBytes(r.texture_payload_bytes).c_str(), (unsigned long long)r.tiles_encoded,
      formatBytes(r.geometry_stored_bytes).c_str(), formatBytes(r.geometry_raw_bytes).c_str(),
      (unsigned long long)p.leaf_copies, (unsigned long long)p.stored,
      (unsigned long long)p.copies_avoided);
  if (r.hint_cells)
    std::printf("  coverage hints: %llu cells, %llu entries, %s, computed in %.2f s\n",
                (unsigned long long)r.hint_cells, (unsigned long long)r.hint_entries,
                formatBytes(r.hint_bytes).c_str(), r.hint_seconds);
}

void printTree(const SceneArchive& scene, const SceneNode& node, uint32_t max_depth,
               nlohmann::json& out, bool json) {
  if (!json)
    std::printf(
        "  %*snode %u: %u children, %u objects, %u textures, %u meshes; block %s, "
        "subtree %u nodes [%llu, +%s)\n",
        int(2 * node.depth), "", node.index, node.child_count, node.object_count,
        node.texture_count, node.mesh_count, formatBytes(node.own.length_bytes).c_str(),
        node.subtree_nodes, (unsigned long long)node.subtree.offset_bytes,
        formatBytes(node.subtree.length_bytes).c_str());
  out.push_back({{"node", node.index},
                 {"depth", node.depth},
                 {"children", node.child_count},
                 {"objects", node.object_count},
                 {"textures", node.texture_count},
                 {"meshes", node.mesh_count},
                 {"own_bytes", node.own.length_bytes},
                 {"subtree_nodes", node.subtree_nodes},
                 {"subtree_offset", node.subtree.offset_bytes},
                 {"subtree_bytes", node.subtree.length_bytes}});
  if (node.depth >= max_depth) return;
  Result<std::vector<SceneNode>> children = scene.children(node);
  if (!children) return;
  for (const SceneNode& child : *children) printTree(scene, child, max_depth, out, json);
}

// Coverage hint statistics (docs/scenes.md, "Coverage hints") for `tessera info`.
nlohmann::json hintSummary(const SceneArchive& scene, bool json) {
  if (scene.coverageHintsRange().length_bytes == 0) {
    if (!json) std::printf("  coverage hints: none\n");
    return nullptr;
  }
  Result<CoverageHints> hints = scene.readCoverageHints();
  if (!hints) {
    if (!json) std::printf("  coverage hints: unreadable: %s\n", hints.error().message.c_str());
    return {{"error", hints.error().message}};
  }
  const CoverageHints& h = *hints;
  size_t most = 0, empty = 0;
  double covered = 0;
  for (uint32_t c = 0; c < h.cellCount(); ++c) {
    most = std::max(most, h.cell(c).size());
    empty += h.cell(c).empty();
    for (const CoverageHint& e : h.cell(c)) covered += e.coverage();
  }
  const double mean = double(h.entries.size()) / h.cellCount();
  if (!json)
    std::printf(
        "  coverage hints: %u x %u cells of %.4g, %u px faces, eyes at %.4g..%.4g; %zu entries "
        "(%.1f textures a cell, at most %zu; %zu cells see none), %s\n",
        h.cells_u, h.cells_v, h.cell_size, h.resolution_px, h.eye_low, h.eye_high, h.entries.size(),
        mean, most, empty, formatBytes(scene.coverageHintsRange().length_bytes).c_str());
  return {{"cells_u", h.cells_u},
          {"cells_v", h.cells_v},
          {"cell_size", h.cell_size},
          {"resolution", h.resolution_px},
          {"eye_low", h.eye_low},
          {"eye_high", h.eye_high},
          {"entries", h.entries.size()},
          {"textures_per_cell_mean", mean},
          {"textures_per_cell_max", most},
          {"cells_seeing_nothing", empty},
          {"coverage_sum_mean", covered / h.cellCount()},
          {"bytes", scene.coverageHintsRange().length_bytes}};
}

}  // namespace

void addSceneBuildOptions(CLI::App& build) {
  SceneCliOptions& o = sceneCliOptions();
  build.add_option("--leaf-capacity", o.leaf_capacity, "Scenes: objects per R-tree leaf")
      ->capture_default_str();
  build.add_option("--fan-out", o.max_children, "Scenes: R-tree children per node (2..256)")
      ->capture_default_str();
  build.add_option("--geometry-codec", o.geometry_codec, "Scenes: meshopt, zstd or raw")
      ->capture_default_str();
  build.add_option("--texture-source", o.texture_sources,
                   "synthetic-scene: images to cut textures from (default: synthetic terrain)");
  build
      .add_option("--max-texture-side", o.max_texture_side_px,
                  "Scenes: largest texture side accepted, px")
      ->capture_default_str();
  build.add_flag("--coverage-hints,!--no-coverage-hints", o.coverage_hints,
                 "Scenes: compute and store average coverage hints (default off: they cost more "
                 "than the rest of the build)");
  build
      .add_option("--hint-cell", o.hint_cell_size,
                  "Scenes: coverage hint cell side, world units (0: the longer ground side / 16)")
      ->capture_default_str();
  build
      .add_option("--hint-resolution", o.hint_resolution_px,
                  "Scenes: coverage hint cube-face resolution, px (1..4096)")
      ->capture_default_str();
}

bool isSceneBuild(const BuildOptions& options) {
  return options.inputs.size() == 1 && isSceneInput(options.inputs[0]);
}

int runSceneBuild(const BuildOptions& options, bool quiet, bool json,
                  const std::atomic<bool>* cancel) {
  const SceneCliOptions& o = sceneCliOptions();
  SceneBuildOptions scene;
  scene.input = options.inputs[0];
  scene.output = options.output;
  scene.texture_sources = o.texture_sources;
  scene.tile_size_px = options.tile_size_px;
  scene.codec = options.codec;
  scene.quality = options.quality;
  scene.effort = options.effort;
  scene.threads = options.threads;
  scene.leaf_capacity = o.leaf_capacity;
  scene.max_children = o.max_children;
  scene.max_texture_side_px = o.max_texture_side_px;
  scene.coverage_hints = o.coverage_hints;
  scene.hint_cell_size = o.hint_cell_size;
  scene.hint_resolution_px = o.hint_resolution_px;
  if (!parseGeometryCodecName(o.geometry_codec, &scene.geometry_codec))
    return reportError({ErrorCode::kInvalidArgument, "unknown geometry codec " + o.geometry_codec});
  const bool show = !quiet && !json && stderrIsTerminal();
  ProgressBar bar("building scene");
  auto on_progress = [&](const SceneBuildProgress& p) {
    if (show)
      bar.update(double(p.textures_done), double(p.textures_total), p.elapsed_s, 1, "textures/s");
  };
  Result<SceneBuildReport> report = buildScene(scene, on_progress, cancel);
  bar.finish();
  if (!report) return reportError(report.error());
  if (!quiet || json) printSceneReport(*report, scene.output, json);
  return kExitOk;
}

void addSceneInfoOptions(CLI::App& info) {
  info.add_option("--tree-depth", sceneCliOptions().tree_depth,
                  "Scene archives: print the R-tree down to this depth")
      ->capture_default_str();
}

bool runSceneInfo(const std::string& path, bool json, int* exit_code) {
  Result<std::shared_ptr<ByteSource>> source = openByteSource(path);
  if (!source) return false;
  Result<std::shared_ptr<SceneArchive>> opened = SceneArchive::open(*source);
  if (!opened) {
    if (opened.error().code == ErrorCode::kNotFound) return false;
    *exit_code = reportError(opened.error());
    return true;
  }
  const SceneArchive& scene = **opened;
  const SceneSummary& s = scene.summary();
  Result<std::string> metadata_text = scene.readMetadata();
  nlohmann::json meta = metadata_text ? nlohmann::json::parse(*metadata_text, nullptr, false)
                                      : nlohmann::json::object();
  const nlohmann::json scene_meta =
      meta.is_object() ? meta.value("scene", nlohmann::json::object()) : nlohmann::json::object();
  nlohmann::json out = {{"path", path},
                        {"file_bytes", scene.fileBytes()},
                        {"format_version", "1.1"},
                        {"objects", s.objects},
                        {"meshes", s.meshes},
                        {"textures", s.textures},
                        {"nodes", s.nodes},
                        {"tree_depth", s.tree_depth},
                        {"max_children", s.max_children},
                        {"leaf_capacity", s.leaf_capacity},
                        {"scene", scene_meta},
                        {"tree", nlohmann::json::array()}};
  if (!json) {
    std::printf(
        "%s: Tessera scene archive 1.1, %s: %u objects, %u meshes, %u textures; R-tree "
        "of %u nodes, depth %u (fan-out %u, leaves of %u)\n",
        path.c_str(), formatBytes(scene.fileBytes()).c_str(), s.objects, s.meshes, s.textures,
        s.nodes, s.tree_depth, s.max_children, s.leaf_capacity);
    if (scene_meta.contains("promotion")) {
      const auto& p = scene_meta["promotion"];
      std::printf(
          "  promotion (Zhou et al., Table 4): %s texture references, %s leaf copies "
          "without promotion, %s stored, %s copies avoided, %s shared; stored per "
          "depth %s\n",
          p.value("texture_references", nlohmann::json()).dump().c_str(),
          p.value("leaf_copies", nlohmann::json()).dump().c_str(),
          p.value("stored", nlohmann::json()).dump().c_str(),
          p.value("copies_avoided", nlohmann::json()).dump().c_str(),
          p.value("shared", nlohmann::json()).dump().c_str(),
          p.value("stored_at_depth", nlohmann::json()).dump().c_str());
    }
    if (scene_meta.contains("bytes")) {
      const auto& b = scene_meta["bytes"];
      std::printf("  sizes: textures %s (coarse block %s), geometry %s (%s raw, %s)\n",
                  formatBytes(b.value("textures", 0ull)).c_str(),
                  formatBytes(b.value("coarse_block", 0ull)).c_str(),
                  formatBytes(b.value("geometry", 0ull)).c_str(),
                  formatBytes(b.value("geometry_raw", 0ull)).c_str(),
                  scene_meta.value("geometry_codec", "?").c_str());
    }
  }
  out["coverage_hints"] = hintSummary(scene, json);
  if (!json) std::printf("  tree (to depth %u):\n", sceneCliOptions().tree_depth);
  Result<SceneNode> root = scene.node(0);
  if (!root) {
    *exit_code = reportError(root.error());
    return true;
  }
  printTree(scene, *root, sceneCliOptions().tree_depth, out["tree"], json);
  if (json) std::printf("%s\n", out.dump(2).c_str());
  *exit_code = kExitOk;
  return true;
}

}  // namespace tessera::cli
