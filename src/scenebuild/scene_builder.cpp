// buildScene: import -> validate -> R-tree -> promotion -> textures encoded to a spool ->
// depth-first layout -> header last, renamed into place.
#include <tessera/scene_build.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <optional>
#include <set>
#include <thread>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "codecs/encode.h"
#include "format/coverage_hints.h"
#include "hint_builder.h"
#include "importers.h"
#include "output/output_file.h"
#include "scene_model.h"
#include "scene_tree.h"
#include "scene_writer.h"
#include "texture_spool.h"

namespace tessera {

using namespace detail;

namespace {

using Clock = std::chrono::steady_clock;
constexpr const char* kSyntheticPrefix = "synthetic-scene:";

std::string extensionOf(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  return ext;
}

Result<void> validateOptions(const SceneBuildOptions& o) {
  if (o.input.empty()) return fail(ErrorCode::kInvalidArgument, "no scene input given");
  if (o.output.empty()) return fail(ErrorCode::kInvalidArgument, "no output path given");
  if (std::filesystem::path(o.input).lexically_normal() ==
      std::filesystem::path(o.output).lexically_normal())
    return fail(ErrorCode::kInvalidArgument, o.input + ": output would overwrite the input");
  if (o.tile_size_px < kMinTileSizePx || o.tile_size_px > kMaxTileSizePx ||
      (o.tile_size_px & (o.tile_size_px - 1)))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("tile size {} is not a power of two in 64..2048", o.tile_size_px));
  if (o.quality < 1 || o.quality > 100)
    return fail(ErrorCode::kInvalidArgument, fmt::format("quality {} out of 1..100", o.quality));
  if (!findEncoder(o.codec) || codecNeedsParent(o.codec))
    return fail(ErrorCode::kUnsupported,
                fmt::format("codec {} is not available for scene textures", codecName(o.codec)));
  if (o.leaf_capacity < 1 || o.leaf_capacity > 65535 || o.max_children < 2 || o.max_children > 256)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("leaf capacity {} or fan-out {} out of 1..65535 and 2..256",
                            o.leaf_capacity, o.max_children));
  return {};
}

Result<ImportedScene> importScene(const SceneBuildOptions& o) {
  if (o.input.rfind(kSyntheticPrefix, 0) == 0)
    return generateSyntheticScene(o.input.substr(std::strlen(kSyntheticPrefix)), o.texture_sources);
  const std::string ext = extensionOf(o.input);
  if (ext == ".gltf" || ext == ".glb") return importGltf(o.input);
  if (ext == ".stg") return importStg(o.input);
  return importAssimp(o.input);
}

// Keeps the meshes and textures some object uses, renumbered in order of first use.
void pruneUnused(ImportedScene& scene) {
  std::vector<uint32_t> mesh_map(scene.meshes.size(), kNoSceneTexture);
  std::vector<uint32_t> texture_map(scene.textures.size(), kNoSceneTexture);
  std::vector<ImportedMesh> meshes;
  std::vector<TextureSource> textures;
  for (ImportedObject& object : scene.objects) {
    if (object.mesh < mesh_map.size()) {
      if (mesh_map[object.mesh] == kNoSceneTexture) {
        mesh_map[object.mesh] = uint32_t(meshes.size());
        meshes.push_back(std::move(scene.meshes[object.mesh]));
      }
      object.mesh = mesh_map[object.mesh];
    }
    for (uint32_t& t : object.textures) {
      if (t == kNoSceneTexture || t >= texture_map.size()) continue;
      if (texture_map[t] == kNoSceneTexture) {
        texture_map[t] = uint32_t(textures.size());
        textures.push_back(std::move(scene.textures[t]));
      }
      t = texture_map[t];
    }
  }
  scene.meshes = std::move(meshes);
  scene.textures = std::move(textures);
}

/// Where every item goes and what promotion did.
struct Placement {
  std::vector<uint32_t> object_order, texture_order, texture_node, texture_users, mesh_order,
      mesh_node;
  PromotionStats stats;
};

// Numbers items in the pre-order of their holder node, ties by first use.
void orderByHolder(const std::vector<uint32_t>& holder, const std::vector<uint32_t>& first_use,
                   std::vector<uint32_t>* order, std::vector<uint32_t>* node) {
  order->resize(holder.size());
  for (uint32_t i = 0; i < holder.size(); ++i) (*order)[i] = i;
  std::sort(order->begin(), order->end(), [&](uint32_t a, uint32_t b) {
    return holder[a] != holder[b] ? holder[a] < holder[b] : first_use[a] < first_use[b];
  });
  node->clear();
  for (uint32_t i : *order) node->push_back(holder[i]);
}

Placement place(const ImportedScene& scene, const SceneTree& tree) {
  Placement p;
  for (const TreeNode& n : tree.nodes)
    p.object_order.insert(p.object_order.end(), n.objects.begin(), n.objects.end());
  std::vector<std::vector<uint32_t>> texture_users(scene.textures.size()),
      mesh_users(scene.meshes.size());
  std::vector<uint32_t> texture_first(scene.textures.size(), UINT32_MAX),
      mesh_first(scene.meshes.size(), UINT32_MAX);
  for (uint32_t k = 0; k < p.object_order.size(); ++k) {
    const uint32_t o = p.object_order[k];
    const ImportedObject& object = scene.objects[o];
    mesh_users[object.mesh].push_back(o);
    mesh_first[object.mesh] = std::min(mesh_first[object.mesh], k);
    for (uint32_t s = 0; s < kSceneTextureSlots; ++s) {
      const uint32_t t = object.textures[s];
      if (t == kNoSceneTexture) continue;
      ++p.stats.texture_references;
      if (texture_users[t].empty() || texture_users[t].back() != o) texture_users[t].push_back(o);
      texture_first[t] = std::min(texture_first[t], k);
    }
  }
  const std::vector<uint32_t> texture_holder = promoteItems(tree, texture_users);
  const std::vector<uint32_t> mesh_holder = promoteItems(tree, mesh_users);
  orderByHolder(texture_holder, texture_first, &p.texture_order, &p.texture_node);
  orderByHolder(mesh_holder, mesh_first, &p.mesh_order, &p.mesh_node);
  p.stats.stored_at_depth.assign(tree.depth, 0);
  for (uint32_t t : p.texture_order) {
    std::set<uint32_t> leaves;
    for (uint32_t o : texture_users[t]) leaves.insert(tree.leaf_of[o]);
    p.texture_users.push_back(uint32_t(texture_users[t].size()));
    p.stats.leaf_copies += leaves.size();
    p.stats.shared += leaves.size() > 1;
    ++p.stats.stored_at_depth[tree.nodes[texture_holder[t]].depth];
  }
  p.stats.stored = p.texture_order.size();
  p.stats.copies_avoided = p.stats.leaf_copies - p.stats.stored;
  return p;
}

nlohmann::json sceneMetadata(const SceneBuildOptions& o, const ImportedScene& scene,
                             const SceneTree& tree, const Placement& p,
                             const std::vector<SpooledTexture>& textures) {
  nlohmann::json images = nlohmann::json::array();
  for (size_t t = 0; t < textures.size(); ++t) {
    const TextureSource& source = scene.textures[p.texture_order[t]];
    images.push_back({{"name", textures[t].info.name},
                      {"source", source.path.empty() ? source.name : source.path},
                      {"width", textures[t].info.width_px},
                      {"height", textures[t].info.height_px},
                      {"channels", textures[t].info.channels}});
  }
  return {{"format", "tessera"},
          {"format_version", "1.1"},
          {"created_by", "tessera build"},
          {"build",
           {{"tile_size", o.tile_size_px},
            {"border", 0},
            {"codec", codecName(o.codec)},
            {"quality", o.quality},
            {"effort", o.effort},
            {"downsample", "box"},
            {"order", "scene-depth-first"}}},
          {"images", images},
          {"scene",
           {{"source", scene.source},
            {"importer", scene.importer},
            {"objects", scene.objects.size()},
            {"meshes", scene.meshes.size()},
            {"textures", textures.size()},
            {"nodes", tree.nodes.size()},
            {"depth", tree.depth},
            {"leaf_capacity", o.leaf_capacity},
            {"max_children", o.max_children},
            {"geometry_codec", geometryCodecName(o.geometry_codec)},
            {"promotion",
             {{"texture_references", p.stats.texture_references},
              {"leaf_copies", p.stats.leaf_copies},
              {"stored", p.stats.stored},
              {"copies_avoided", p.stats.copies_avoided},
              {"shared", p.stats.shared},
              {"stored_at_depth", p.stats.stored_at_depth}}}}}};
}

// The scene in world space, textures in the archive's numbering, for the hint builder.
HintScene hintSceneOf(const ImportedScene& scene, const Placement& p) {
  HintScene out;
  std::vector<uint32_t> final_texture(scene.textures.size(), kNoSceneTexture);
  for (uint32_t t = 0; t < p.texture_order.size(); ++t) final_texture[p.texture_order[t]] = t;
  out.texture_count = uint32_t(p.texture_order.size());
  out.bounds = scene.objects.empty() ? SceneBox{} : scene.objects[0].bounds;
  out.object_first.push_back(0);
  for (const ImportedObject& object : scene.objects) {
    const ImportedMesh& mesh = scene.meshes[object.mesh];
    const std::array<float, 12>& m = object.transform;
    for (uint32_t index : mesh.indices) {
      const float* v = mesh.positions.data() + 3 * size_t(index);
      for (int r = 0; r < 3; ++r)
        out.triangles.push_back(m[4 * r] * v[0] + m[4 * r + 1] * v[1] + m[4 * r + 2] * v[2] +
                                m[4 * r + 3]);
    }
    out.object_first.push_back(uint32_t(out.triangles.size() / 9));
    out.object_bounds.push_back(object.bounds);
    std::array<uint32_t, kSceneTextureSlots> slots;
    for (uint32_t k = 0; k < kSceneTextureSlots; ++k)
      slots[k] = object.textures[k] == kNoSceneTexture ? kNoSceneTexture
                                                       : final_texture[object.textures[k]];
    out.object_textures.push_back(slots);
    for (int a = 0; a < 3; ++a) {
      out.bounds.min[a] = std::min(out.bounds.min[a], object.bounds.min[a]);
      out.bounds.max[a] = std::max(out.bounds.max[a], object.bounds.max[a]);
    }
  }
  return out;
}

}  // namespace

bool isSceneInput(const std::string& input) {
  if (input.rfind(kSyntheticPrefix, 0) == 0) return true;
  static const std::set<std::string> kExtensions = {".gltf", ".glb", ".obj", ".dae", ".ac", ".stg"};
  return kExtensions.count(extensionOf(input)) > 0;
}

Result<SceneBuildReport> buildScene(
    const SceneBuildOptions& options,
    const std::function<void(const SceneBuildProgress&)>& on_progress,
    const std::atomic<bool>* cancel) {
  const auto start = Clock::now();
  TESSERA_TRY(validateOptions(options));
  TESSERA_ASSIGN_OR_RETURN(ImportedScene scene, importScene(options));
  pruneUnused(scene);
  TESSERA_TRY(validateScene(scene));
  if (scene.textures.empty())
    return fail(ErrorCode::kUnsupported,
                scene.source + ": no object has a texture; a scene archive holds at least one");

  std::vector<SceneBox> boxes;
  boxes.reserve(scene.objects.size());
  for (const ImportedObject& object : scene.objects) boxes.push_back(object.bounds);
  const SceneTree tree = buildSceneTree(boxes, options.leaf_capacity, options.max_children);
  if (tree.depth > kMaxSceneDepth || tree.nodes.size() > kMaxSceneNodes)
    return fail(ErrorCode::kTooLarge, scene.source + ": the R-tree is too deep or too large");
  const Placement placement = place(scene, tree);
  std::optional<CoverageHints> hints;
  HintBuildStats hint_stats;
  if (options.coverage_hints) {
    HintBuildOptions hint_options;
    hint_options.cell_size = options.hint_cell_size;
    hint_options.resolution_px = options.hint_resolution_px;
    hint_options.threads =
        options.threads ? options.threads : std::max(1u, std::thread::hardware_concurrency());
    TESSERA_ASSIGN_OR_RETURN(
        hints, buildCoverageHints(hintSceneOf(scene, placement), hint_options, &hint_stats));
  }

  TESSERA_ASSIGN_OR_RETURN(TempFile out, TempFile::create(options.output));
  TESSERA_ASSIGN_OR_RETURN(TempFile spool, TempFile::create(options.output));
  TextureSpoolOptions spool_options;
  spool_options.tile_size_px = options.tile_size_px;
  spool_options.codec = options.codec;
  spool_options.quality = options.quality;
  spool_options.effort = options.effort;
  spool_options.max_side_px = options.max_texture_side_px;
  spool_options.threads =
      options.threads ? options.threads : std::max(1u, std::thread::hardware_concurrency());
  uint64_t spool_bytes = 0;
  const uint64_t total = placement.texture_order.size();
  auto on_done = [&](uint64_t done) {
    if (on_progress)
      on_progress({done, total, std::chrono::duration<double>(Clock::now() - start).count()});
  };
  TESSERA_ASSIGN_OR_RETURN(std::vector<SpooledTexture> textures,
                           spoolTextures(scene, placement.texture_order, spool_options, spool,
                                         &spool_bytes, on_done, cancel));

  SceneLayoutInput input;
  input.scene = &scene;
  input.tree = &tree;
  input.object_order = placement.object_order;
  input.mesh_order = placement.mesh_order;
  input.mesh_node = placement.mesh_node;
  input.texture_order = placement.texture_order;
  input.texture_node = placement.texture_node;
  input.texture_users = placement.texture_users;
  input.spool = &spool;
  input.spool_bytes = spool_bytes;
  input.geometry_codec = GeometryCodecId(options.geometry_codec);
  input.leaf_capacity = options.leaf_capacity;
  input.max_children = options.max_children;
  input.metadata = sceneMetadata(options, scene, tree, placement, textures);
  if (hints) {
    input.hints = &*hints;
    input.metadata["scene"]["coverage_hints"] = {{"cells_u", hints->cells_u},
                                                 {"cells_v", hints->cells_v},
                                                 {"cell_size", hints->cell_size},
                                                 {"resolution", hints->resolution_px},
                                                 {"eye_low", hints->eye_low},
                                                 {"eye_high", hints->eye_high},
                                                 {"entries", hints->entries.size()},
                                                 {"views", hint_stats.views},
                                                 {"objects_drawn", hint_stats.objects_drawn}};
  }
  SceneBuildReport report;
  for (const SpooledTexture& t : textures) report.tiles_encoded += t.tiles_encoded;
  input.textures = std::move(textures);
  TESSERA_ASSIGN_OR_RETURN(SceneLayoutResult written, writeSceneArchive(input, out));
  if (cancel && cancel->load())
    return fail(ErrorCode::kCancelled, options.output + ": build cancelled");
  TESSERA_TRY(out.commit());

  report.summary = {uint32_t(tree.nodes.size()),
                    uint32_t(scene.objects.size()),
                    uint32_t(scene.meshes.size()),
                    uint32_t(scene.textures.size()),
                    tree.depth,
                    options.max_children,
                    options.leaf_capacity,
                    Box3{tree.nodes[0].bounds.min, tree.nodes[0].bounds.max}};
  report.promotion = placement.stats;
  report.output_bytes = written.file_bytes;
  report.texture_payload_bytes = written.texture_payload_bytes + written.coarse_bytes;
  report.geometry_raw_bytes = written.geometry_raw_bytes;
  report.geometry_stored_bytes = written.geometry_stored_bytes;
  report.importer = scene.importer;
  if (hints) {
    report.hint_cells = hints->cellCount();
    report.hint_entries = hints->entries.size();
    report.hint_bytes = written.hint_bytes;
    report.hint_seconds = hint_stats.seconds;
  }
  report.elapsed_s = std::chrono::duration<double>(Clock::now() - start).count();
  return report;
}

}  // namespace tessera
