#include <tessera/scene_stream.h>

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include <tessera/check.h>

#include "format/directory.h"
#include "io_plan.h"
#include "scene_hints.h"
#include "scene_loader.h"
#include "scene_lod.h"
#include "scene_residency.h"

namespace tessera {

using detail::LevelRef;
using detail::PlanNode;

const char* readGranularityName(ReadGranularity granularity) {
  switch (granularity) {
    case ReadGranularity::kObject: return "object";
    case ReadGranularity::kNode: return "node";
    case ReadGranularity::kSubtree: return "subtree";
  }
  return "?";
}

LinkCost measureLinkCost(const ByteSource& source, const LinkCost& fallback) {
  const std::optional<LinkStats> stats = source.linkStats();
  // A network source is measured from its first request on (the open's): planning the first
  // frame's reads with a local disk's costs would ask a 40 ms link for many small reads.
  if (!stats || stats->recent.empty()) return fallback;
  std::vector<double> first_byte;
  double bytes = 0, transfer_s = 0;
  for (const LinkSample& sample : stats->recent) {
    first_byte.push_back(sample.first_byte_seconds);
    bytes += double(sample.bytes);
    transfer_s += std::max(0.0, sample.seconds - sample.first_byte_seconds);
  }
  std::nth_element(first_byte.begin(), first_byte.begin() + first_byte.size() / 2,
                   first_byte.end());
  LinkCost cost;
  cost.latency_s = first_byte[first_byte.size() / 2];
  // Transfers too short to time (a cached response) say nothing about the bandwidth.
  cost.bandwidth_bytes_per_s =
      transfer_s > 1e-4 ? bytes / transfer_s : fallback.bandwidth_bytes_per_s;
  return cost;
}

namespace {

enum class NodeState : uint8_t { kUnknown, kInFlight, kKnown, kFailed };

bool sameCamera(const PerspectiveView& a, const PerspectiveView& b) {
  return a.eye_x == b.eye_x && a.eye_y == b.eye_y && a.eye_z == b.eye_z && a.yaw_rad == b.yaw_rad &&
         a.pitch_rad == b.pitch_rad && a.fov_y_rad == b.fov_y_rad && a.viewport_w == b.viewport_w &&
         a.viewport_h == b.viewport_h;
}

// Texel bytes of every level, 4 per texel whatever the channels (what a GPU holds).
std::vector<std::vector<uint64_t>> levelBytes(const std::vector<SceneTexture>& textures) {
  std::vector<std::vector<uint64_t>> out(textures.size());
  for (size_t t = 0; t < textures.size(); ++t) {
    const ImageInfo& info = textures[t].info;
    for (uint32_t level = 0; level < std::max(1u, info.level_count); ++level) {
      out[t].push_back(uint64_t(info.levelWidthPx(level)) * info.levelHeightPx(level) * 4);
    }
  }
  return out;
}

// The byte hull of a level's encoded tiles: one object-granularity read (a node stores a
// texture's level contiguously, coarse to fine across its textures).
// A level of uniform tiles only has no bytes: an empty range at `fallback_offset` (its node's
// block) so that the read serving that node carries it.
FileRange levelHull(const std::vector<TileEntry>& tiles, uint64_t fallback_offset) {
  uint64_t begin = UINT64_MAX, end = 0;
  for (const TileEntry& tile : tiles) {
    if (tile.kind != TileKind::kEncoded) continue;
    begin = std::min(begin, tile.offset_bytes);
    end = std::max(end, tile.offset_bytes + tile.length_bytes);
  }
  return begin == UINT64_MAX ? FileRange{fallback_offset, 0} : FileRange{begin, end - begin};
}

// Per node: its head and the directory pages of the textures it stores, the prefix of its
// block a reader needs before it can read single meshes and levels (the writer puts the pages
// right after the head; parseNode checks that they are inside).
std::vector<uint64_t> headAndPagesBytes(const std::vector<SceneNode>& nodes,
                                        const std::vector<SceneTexture>& textures) {
  std::vector<uint64_t> out(nodes.size(), 0);
  for (const SceneNode& node : nodes) out[node.index] = node.head_bytes;
  for (const SceneTexture& texture : textures) {
    if (texture.node >= out.size()) continue;
    for (uint32_t level = 0; level < texture.info.level_count; ++level) {
      out[texture.node] += uint64_t(texture.info.tilesX(level)) * texture.info.tilesY(level) *
                           detail::kTileEntryBytes;
    }
  }
  return out;
}

// Leaves asked for, and textures refined, per free read slot: neighbours' reads join
// (mergePieces, joinReads), so a slot serves several.
constexpr uint32_t kWantsPerSlot = 16;

}  // namespace

struct SceneStreamer::Impl {
  SceneStreamOptions options;
  std::shared_ptr<const SceneArchive> archive;
  std::shared_ptr<const detail::LoaderContext> context;
  std::vector<SceneNode> nodes;
  std::vector<uint32_t> parent;  ///< parent[0] == 0
  std::vector<NodeState> node_state;
  std::vector<std::vector<uint32_t>> leaf_objects;  ///< per node, once known
  /// Per node, once known: min over its objects' textures of max(w, h) / (longest side *
  /// 2^coarsest). A leaf at distance d with d * pixelAngle * 2^bias * ratio >= 1 needs only
  /// coarsest levels (levelFor), so its objects skip the per-texture work.
  std::vector<double> leaf_coarse_ratio;
  std::vector<std::vector<NodeTexture>> node_textures;  ///< per node, once known
  std::vector<const NodeTexture*> holder_entry;         ///< per texture, once its node is known
  std::vector<SceneObject> objects;
  std::vector<bool> object_known;
  std::vector<std::unique_ptr<MeshData>> meshes;
  std::vector<SceneMesh> mesh_records;  ///< per mesh, once its node is known
  std::vector<bool> mesh_record_known;
  std::vector<bool> mesh_busy;  ///< an object read of its blob is queued or running
  /// Meshes of visible objects whose node is known but whose blob is not loaded (the node was
  /// read as a prefix), gathered each frame.
  std::vector<uint32_t> missing_meshes;
  std::vector<uint64_t> prefix_bytes;  ///< per node: headAndPagesBytes
  std::vector<uint32_t> mesh_holder;   ///< per mesh: the node storing it
  std::vector<Image> coarsest;
  std::vector<bool> coarsest_known;
  std::vector<std::vector<std::vector<Image>>> levels;  ///< [texture][level] tiles
  detail::SceneResidency residency;
  std::vector<bool> level_busy;            ///< a refinement of the texture is queued or running
  std::vector<uint32_t> levels_in_flight;  ///< per texture: its levels queued or running
  /// Decoded levels finer than their texture's next one, waiting for it (another read).
  std::vector<detail::DecodedLevel> early_levels;
  std::unique_ptr<detail::CellHints> hints;  ///< null: coverage hints not used
  std::vector<uint64_t> demanded_frame;      ///< per texture: the last frame of a feedback demand
  uint64_t frame = 0;
  std::unique_ptr<detail::SceneLoaderPool> pool;  // last: its workers stop before the rest goes

  PerspectiveView last_camera;
  bool first_frame = true;
  uint32_t still_frames = 0;
  bool camera_changed = true;         ///< this frame's camera differs from the last one's
  uint32_t node_reads_in_flight = 0;  ///< queued or running reads that parse nodes
  std::vector<uint32_t> drawable;
  std::vector<uint32_t> visible_leaves;
  std::vector<bool> leaf_inside;  ///< per visible leaf: wholly inside the frustum
  std::vector<detail::TextureDemand> demands;
  /// The planner's view of every node, kept between frames: only `wanted` and `pieces`
  /// change, and only for the nodes in `plan_touched`, reset after each plan.
  std::vector<PlanNode> plan;
  std::vector<uint32_t> plan_touched;
  SceneStreamTotals totals;

  explicit Impl(std::vector<std::vector<uint64_t>> level_bytes)
      : residency(std::move(level_bytes)) {}

  LinkCost link() const {
    return options.link ? *options.link : measureLinkCost(archive->source());
  }
  void applyResults(SceneFrameStats& stats);
  void applyResult(detail::ReadResult& result);
  void applyLevel(detail::DecodedLevel& level);
  void applyEarlyLevels();
  void levelSettled(uint32_t texture) {
    if (levels_in_flight[texture] > 0 && --levels_in_flight[texture] == 0)
      level_busy[texture] = false;
  }
  void queryVisible(const detail::Frustum& frustum);
  void collectDemands(const PerspectiveView& camera, const detail::Frustum& frustum,
                      uint64_t budget, SceneFrameStats& stats);
  void applyHints(const PerspectiveView& camera, const detail::Frustum& frustum, uint64_t budget,
                  SceneFrameStats& stats);
  std::vector<uint32_t> leavesToRead(uint32_t slots) const;
  void evict(uint64_t budget, SceneFrameStats& stats);
  void planAndSubmit(const PerspectiveView& camera, uint64_t budget, bool moving,
                     SceneFrameStats& stats);
  /// A large inner node is first read as its head and pages only (a prefix of its block):
  /// shared meshes and textures gather at the top of the tree (seed 004's promotion), and a
  /// view needs a few of them, read next as object reads, rather than the whole block.
  bool readPrefixFirst(uint32_t node, const LinkCost& cost) const {
    const uint64_t own = nodes[node].own.length_bytes, prefix = prefix_bytes[node];
    if (nodes[node].isLeaf() || prefix >= own) return false;
    return double(own - prefix) / cost.bandwidth_bytes_per_s > 2 * cost.latency_s;
  }
  void wantMeshes(std::vector<SceneMesh>& jobs);
  void want(uint32_t node) {
    if (!plan[node].wanted) plan_touched.push_back(node);
    plan[node].wanted = true;
  }
  std::vector<detail::LevelJob> addRefinements(uint64_t budget, bool moving, uint32_t slots);
  void submitPlan(const PerspectiveView& camera, std::vector<detail::LevelJob>& refinements,
                  std::vector<SceneMesh>& mesh_jobs, SceneFrameStats& stats);
};

SceneStreamer::SceneStreamer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
SceneStreamer::~SceneStreamer() = default;

Result<std::unique_ptr<SceneStreamer>> SceneStreamer::open(
    std::shared_ptr<const SceneArchive> archive, const SceneStreamOptions& options) {
  TESSERA_CHECK(archive != nullptr) << "SceneStreamer::open: null archive";
  auto context = std::make_shared<detail::LoaderContext>();
  context->archive = archive;
  // Over a network, ask for the three at once: the coarse block, and the node table with the
  // texture table the builder appends right after it (two requests, one round trip).
  const FileRange node_table = archive->nodeTableRange(), coarse = archive->coarseRange();
  const uint64_t tables_end =
      std::min(archive->fileBytes(), node_table.offset_bytes + node_table.length_bytes +
                                         uint64_t(archive->summary().textures) * 64);
  std::vector<ByteRange> open_reads = {
      {node_table.offset_bytes, tables_end - node_table.offset_bytes},
      {coarse.offset_bytes, coarse.length_bytes}};
  // The coverage hints too, when they will be read: still the same round trip.
  if (const FileRange hint_range = archive->coverageHintsRange();
      !options.coverage_hints && options.use_coverage_hints && hint_range.length_bytes != 0)
    open_reads.push_back({hint_range.offset_bytes, hint_range.length_bytes});
  archive->source().prefetch(open_reads);
  TESSERA_ASSIGN_OR_RETURN(std::vector<SceneNode> nodes, archive->allNodes());
  TESSERA_ASSIGN_OR_RETURN(context->textures, archive->textures(0, archive->summary().textures));
  context->coarse_block.resize(coarse.length_bytes);
  context->coarse_offset_bytes = coarse.offset_bytes;
  TESSERA_TRY(archive->source().read(coarse.offset_bytes, context->coarse_block));

  auto impl = std::make_unique<Impl>(levelBytes(context->textures));
  impl->options = options;
  impl->archive = archive;
  const size_t node_count = nodes.size(), texture_count = context->textures.size();
  impl->parent.assign(node_count, 0);
  for (uint32_t i = 0; i < node_count; ++i) {
    const uint32_t end = i + nodes[i].subtree_nodes;
    for (uint32_t c = i + 1; c < end; c += nodes[c].subtree_nodes) impl->parent[c] = i;
  }
  impl->nodes = std::move(nodes);
  impl->node_state.assign(node_count, NodeState::kUnknown);
  impl->leaf_objects.resize(node_count);
  impl->leaf_coarse_ratio.assign(node_count, INFINITY);
  impl->node_textures.resize(node_count);
  impl->holder_entry.assign(texture_count, nullptr);
  impl->objects.resize(archive->summary().objects);
  impl->object_known.assign(archive->summary().objects, false);
  impl->meshes.resize(archive->summary().meshes);
  impl->mesh_records.resize(archive->summary().meshes);
  impl->mesh_record_known.assign(archive->summary().meshes, false);
  impl->mesh_busy.assign(archive->summary().meshes, false);
  impl->prefix_bytes = headAndPagesBytes(impl->nodes, context->textures);
  impl->mesh_holder.assign(archive->summary().meshes, 0);
  for (const SceneNode& node : impl->nodes) {
    for (uint32_t m = node.first_mesh; m < node.first_mesh + node.mesh_count; ++m) {
      if (m < impl->mesh_holder.size()) impl->mesh_holder[m] = node.index;
    }
  }
  impl->coarsest.resize(texture_count);
  impl->coarsest_known.assign(texture_count, false);
  impl->levels.resize(texture_count);
  impl->level_busy.assign(texture_count, false);
  impl->levels_in_flight.assign(texture_count, 0);
  impl->plan.resize(node_count);
  for (uint32_t i = 0; i < node_count; ++i) {
    impl->plan[i].subtree_nodes = impl->nodes[i].subtree_nodes;
    impl->plan[i].own = impl->nodes[i].own;
    impl->plan[i].subtree = impl->nodes[i].subtree;
  }
  std::shared_ptr<const CoverageHints> hints = options.coverage_hints;
  if (!hints && options.use_coverage_hints && archive->coverageHintsRange().length_bytes != 0) {
    TESSERA_ASSIGN_OR_RETURN(CoverageHints read, archive->readCoverageHints());
    hints = std::make_shared<const CoverageHints>(std::move(read));
  }
  if (hints && options.use_coverage_hints) {
    if (hints->texture_count != texture_count)
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}: coverage hints for {} textures, the scene has {}",
                              archive->name(), hints->texture_count, texture_count));
    std::vector<uint32_t> texture_node;
    for (const SceneTexture& texture : context->textures)
      texture_node.push_back(std::min<uint32_t>(texture.node, uint32_t(node_count - 1)));
    impl->hints =
        std::make_unique<detail::CellHints>(hints, std::move(texture_node), uint32_t(node_count));
    impl->demanded_frame.assign(texture_count, 0);
  }
  impl->context = context;
  impl->pool = std::make_unique<detail::SceneLoaderPool>(context, options.worker_threads);
  return std::unique_ptr<SceneStreamer>(new SceneStreamer(std::move(impl)));
}

void SceneStreamer::Impl::applyResult(detail::ReadResult& result) {
  for (const detail::LevelJob& level : result.job.levels) levelSettled(level.texture);
  for (const SceneMesh& mesh : result.job.meshes) mesh_busy[mesh.index] = false;
  if (!result.job.parse.empty()) --node_reads_in_flight;
  if (!result.error.empty()) {
    // A node that failed to read or parse is not asked for again: retrying a corrupt block
    // every frame would only repeat the error.
    ++totals.read_errors;
    const uint64_t read_end =
        result.job.read.range.offset_bytes + result.job.read.range.length_bytes;
    for (const SceneNode& node : result.job.parse) {
      // A prefix that did not hold the pages (an archive written in another order): read the
      // whole block next time.
      const bool prefix = read_end < node.own.offset_bytes + node.own.length_bytes;
      node_state[node.index] = prefix ? NodeState::kUnknown : NodeState::kFailed;
      if (prefix) prefix_bytes[node.index] = node.own.length_bytes;
    }
    return;
  }
  for (detail::ParsedNode& parsed : result.nodes) {
    for (const SceneObject& object : parsed.contents.objects) {
      if (object.index >= objects.size()) continue;
      objects[object.index] = object;
      object_known[object.index] = true;
      leaf_objects[parsed.node].push_back(object.index);
      const double side = detail::longestSide(object.bounds);
      for (uint32_t t : object.textures) {
        if (t == kNoTexture || t >= context->textures.size() || !(side > 0)) continue;
        const ImageInfo& info = context->textures[t].info;
        const double ratio = double(std::max(info.width_px, info.height_px)) /
                             std::ldexp(side, int(std::max(1u, info.level_count) - 1));
        leaf_coarse_ratio[parsed.node] = std::min(leaf_coarse_ratio[parsed.node], ratio);
      }
    }
    for (const SceneMesh& mesh : parsed.contents.meshes) {
      if (mesh.index >= mesh_records.size()) continue;
      mesh_records[mesh.index] = mesh;
      mesh_record_known[mesh.index] = true;
    }
    node_textures[parsed.node] = std::move(parsed.contents.textures);
    for (const NodeTexture& texture : node_textures[parsed.node]) {
      if (texture.texture < holder_entry.size()) holder_entry[texture.texture] = &texture;
    }
    node_state[parsed.node] = NodeState::kKnown;
  }
  for (detail::DecodedMesh& mesh : result.meshes) {
    if (mesh.mesh < meshes.size())
      meshes[mesh.mesh] = std::make_unique<MeshData>(std::move(mesh.data));
  }
  for (detail::DecodedCoarsest& tile : result.coarsest) {
    if (coarsest_known[tile.texture]) continue;
    coarsest[tile.texture] = std::move(tile.tile);
    coarsest_known[tile.texture] = true;
  }
  for (detail::DecodedLevel& level : result.levels) {
    // A level of a chain read in several reads can arrive before its coarser neighbour.
    if (level.level + 1 < residency.resident(level.texture)) {
      early_levels.push_back(std::move(level));
      continue;
    }
    applyLevel(level);
  }
}

void SceneStreamer::Impl::applyLevel(detail::DecodedLevel& level) {
  // A level that no longer extends the chain (evicted meanwhile) is dropped.
  if (!residency.loaded({level.texture, level.level})) return;
  auto& texture_levels = levels[level.texture];
  if (texture_levels.size() <= level.level)
    texture_levels.resize(residency.coarsest(level.texture) + 1);
  texture_levels[level.level] = std::move(level.tiles);
}

void SceneStreamer::Impl::applyEarlyLevels() {
  for (bool progress = true; progress;) {
    progress = false;
    for (size_t i = 0; i < early_levels.size();) {
      detail::DecodedLevel& level = early_levels[i];
      const uint32_t resident = residency.resident(level.texture);
      if (level.level + 1 < resident && levels_in_flight[level.texture] > 0) {
        ++i;  // its coarser neighbour is still on its way
        continue;
      }
      if (level.level + 1 == resident) {
        applyLevel(level);
        progress = true;
      }
      // Applied, already resident, or orphaned (its coarser neighbour failed or was dropped).
      early_levels[i] = std::move(early_levels.back());
      early_levels.pop_back();
    }
  }
}

void SceneStreamer::Impl::applyResults(SceneFrameStats& stats) {
  std::vector<detail::ReadResult> results = pool->drain();
  for (detail::ReadResult& result : results) applyResult(result);
  applyEarlyLevels();
  stats.results_applied = uint32_t(results.size());
}

void SceneStreamer::Impl::queryVisible(const detail::Frustum& frustum) {
  visible_leaves.clear();
  leaf_inside.clear();
  // Depth-first: a node's children start at index + 1 and follow each other's subtrees. A
  // subtree wholly inside the frustum is taken without testing below it (inside_end).
  uint32_t i = 0, inside_end = 0;
  const uint32_t count = uint32_t(nodes.size());
  while (i < count) {
    const SceneNode& node = nodes[i];
    if (i >= inside_end) {
      if (!detail::boxMayBeVisible(frustum, node.bounds)) {
        i += node.subtree_nodes;
        continue;
      }
      if (detail::boxInside(frustum, node.bounds)) inside_end = i + node.subtree_nodes;
    }
    if (node.isLeaf()) {
      visible_leaves.push_back(i);
      leaf_inside.push_back(i < inside_end);
    }
    ++i;
  }
}

void SceneStreamer::Impl::collectDemands(const PerspectiveView& camera,
                                         const detail::Frustum& frustum, uint64_t budget,
                                         SceneFrameStats& stats) {
  demands.clear();
  drawable.clear();
  missing_meshes.clear();
  const detail::LodFrame lod_frame = detail::lodFrame(camera, options.lod_bias);
  for (size_t v = 0; v < visible_leaves.size(); ++v) {
    const uint32_t leaf = visible_leaves[v];
    if (node_state[leaf] != NodeState::kKnown) {
      ++stats.waiting_leaves;
      continue;
    }
    // Far enough that every texture of every object wants its coarsest: no demand to make.
    const bool far = detail::distanceToBox(camera, nodes[leaf].bounds) * lod_frame.pixel_angle *
                         lod_frame.bias_scale * leaf_coarse_ratio[leaf] >=
                     1;
    for (uint32_t o : leaf_objects[leaf]) {
      const SceneObject& object = objects[o];
      if (!leaf_inside[v] && !detail::boxMayBeVisible(frustum, object.bounds)) continue;
      ++stats.visible_objects;
      if (object.mesh < meshes.size() && !meshes[object.mesh] && mesh_record_known[object.mesh] &&
          !mesh_busy[object.mesh]) {
        missing_meshes.push_back(object.mesh);
      }
      bool textured = true;
      const detail::ObjectScale scale =
          far ? detail::ObjectScale{} : detail::objectScale(lod_frame, object.bounds);
      for (uint32_t t : object.textures) {
        if (t == kNoTexture || t >= coarsest_known.size()) continue;
        if (far) {
          textured = textured && coarsest_known[t];
          continue;
        }
        const uint32_t level = detail::levelFor(lod_frame, scale, context->textures[t].info);
        demands.push_back({t, level, scale.pixels});
        textured = textured && coarsest_known[t];
        if (residency.resident(t) > level) stats.missing_pixels += scale.pixels;
      }
      // Drawn only with its geometry and at least the coarsest level of every texture.
      if (textured && object.mesh < meshes.size() && meshes[object.mesh]) drawable.push_back(o);
    }
  }
  applyHints(camera, frustum, budget, stats);
  residency.setDemand(demands);
}

void SceneStreamer::Impl::applyHints(const PerspectiveView& camera, const detail::Frustum& frustum,
                                     uint64_t budget, SceneFrameStats& stats) {
  if (!hints || !hints->setCamera(camera)) return;
  stats.hinted = true;
  ++frame;
  // With feedback: the projected size bounds what the objects can cover, the cell's samples
  // discount what they found hidden; the smaller ranks the load (and the eviction). The level
  // stays the projected-size estimate's: it is what the screen resolves.
  for (detail::TextureDemand& demand : demands) {
    const double hinted = std::max(hints->pixels(demand.texture), hints->floorPixels());
    demand.pixels = std::min(demand.pixels, uint64_t(hinted));
    demanded_frame[demand.texture] = frame;
  }
  // Before feedback (seed 003): a texture the cell sees whose users have not arrived gets the
  // level its hint pixels need, no finer than its share of the budget by hint allows, when its
  // node is known and may be in view.
  for (uint32_t t : hints->textures()) {
    if (demanded_frame[t] == frame || !holder_entry[t]) continue;
    if (!detail::boxMayBeVisible(frustum, nodes[context->textures[t].node].bounds)) continue;
    const double pixels = hints->pixels(t);
    const uint32_t coarsest_level = residency.coarsest(t);
    uint32_t level = detail::levelForPixels(context->textures[t].info, pixels, options.lod_bias);
    const double share = double(budget) * pixels / hints->totalPixels();
    // S(L), the pyramid from L down: about 4/3 of level L.
    for (; level < coarsest_level; ++level) {
      if (double(residency.levelBytes(t, level)) * 4 / 3 <= share) break;
    }
    demands.push_back({t, level, uint64_t(pixels)});
    ++stats.hint_only_textures;
  }
}

std::vector<uint32_t> SceneStreamer::Impl::leavesToRead(uint32_t slots) const {
  std::vector<uint32_t> leaves;
  for (uint32_t leaf : visible_leaves)
    if (node_state[leaf] == NodeState::kUnknown) leaves.push_back(leaf);
  if (!hints || !hints->active()) {
    if (leaves.size() > slots) leaves.resize(slots);
    return leaves;
  }
  // The hinted pixels a read of the leaf brings: its textures' and its unread ancestors'.
  std::vector<std::pair<double, uint32_t>> ranked;
  for (uint32_t leaf : leaves) {
    double pixels = 0;
    for (uint32_t n = leaf;; n = parent[n]) {
      if (n == leaf || node_state[n] == NodeState::kUnknown) pixels += hints->nodePixels(n);
      if (n == 0) break;
    }
    ranked.push_back({-pixels, leaf});
  }
  const size_t take = std::min<size_t>(slots, ranked.size());
  std::partial_sort(ranked.begin(), ranked.begin() + take, ranked.end());
  leaves.clear();
  for (size_t k = 0; k < take; ++k) leaves.push_back(ranked[k].second);
  return leaves;
}

void SceneStreamer::Impl::evict(uint64_t budget, SceneFrameStats& stats) {
  for (const LevelRef& level : residency.evictTo(budget)) {
    levels[level.texture][level.level] = {};
    levels[level.texture][level.level].shrink_to_fit();
    ++stats.levels_evicted;
  }
}

std::vector<detail::LevelJob> SceneStreamer::Impl::addRefinements(uint64_t budget, bool moving,
                                                                  uint32_t slots) {
  std::vector<detail::LevelJob> jobs;
  const LinkCost cost = link();
  const double limit_s =
      moving ? options.moving_level_time_limit_s : options.still_level_time_limit_s;
  const size_t max_textures = size_t(slots) * kWantsPerSlot;
  uint64_t planned_bytes = residency.budgetedBytes();
  size_t textures = 0;
  for (const LevelRef& ref : residency.nextLoads(budget, level_busy)) {
    if (textures >= max_textures) break;
    const NodeTexture* entry = holder_entry[ref.texture];
    if (!entry || ref.level >= entry->levels.size()) continue;  // its node is not known yet
    const uint32_t holder = context->textures[ref.texture].node;
    // The whole chain down to the wanted level at once (coarse to fine), not one level per
    // round trip, while it fits the budget; the next level alone is nextLoads' to admit.
    for (uint32_t level = ref.level + 1; level-- > residency.wanted(ref.texture);) {
      const uint64_t bytes = residency.levelBytes(ref.texture, level);
      if (level != ref.level && planned_bytes + bytes > budget) break;
      const FileRange hull = levelHull(entry->levels[level], nodes[holder].own.offset_bytes);
      // Seed 003 part III: a level that would take longer than the limit waits for a stiller
      // camera (or a faster link).
      if (detail::readCost(cost, hull.length_bytes) > limit_s) break;
      want(holder);
      plan[holder].pieces.push_back(hull);
      jobs.push_back({ref.texture, level, hull, entry->info, entry->levels[level]});
      planned_bytes += bytes;
      ++levels_in_flight[ref.texture];
      level_busy[ref.texture] = true;
    }
    ++textures;
  }
  return jobs;
}

void SceneStreamer::Impl::wantMeshes(std::vector<SceneMesh>& jobs) {
  for (uint32_t m : missing_meshes) {
    if (mesh_busy[m]) continue;  // two visible objects share it
    const SceneMesh& mesh = mesh_records[m];
    const uint32_t holder = mesh_holder[m];
    want(holder);
    plan[holder].pieces.push_back(mesh.blob);
    jobs.push_back(mesh);
    mesh_busy[m] = true;
  }
}

void SceneStreamer::Impl::submitPlan(const PerspectiveView& camera,
                                     std::vector<detail::LevelJob>& refinements,
                                     std::vector<SceneMesh>& mesh_jobs, SceneFrameStats& stats) {
  const LinkCost cost = link();
  for (const detail::JoinedRead& joined : detail::joinReads(detail::planReads(plan, cost), cost)) {
    const PlannedRead& read = joined.read;
    detail::ReadJob job;
    job.read = read;
    job.camera = camera;
    job.lod_bias = options.lod_bias;
    const uint64_t begin = read.range.offset_bytes, end = begin + read.range.length_bytes;
    // Every unknown node a part holds is parsed: its bytes are here already.
    for (const PlannedRead& part : joined.parts) {
      const uint32_t last = part.granularity == ReadGranularity::kSubtree
                                ? part.node + nodes[part.node].subtree_nodes
                                : part.node + 1;
      for (uint32_t n = part.node; n < last; ++n) {
        if (node_state[n] == NodeState::kUnknown) {
          node_state[n] = NodeState::kInFlight;
          job.parse.push_back(nodes[n]);
        }
      }
    }
    for (detail::LevelJob& level : refinements) {
      const FileRange& hull = level.hull;
      if (level.tiles.empty() || hull.offset_bytes < begin ||
          hull.offset_bytes + hull.length_bytes > end) {
        continue;
      }
      job.levels.push_back(std::move(level));
      level.tiles.clear();  // taken: a level goes to the first read that holds it
    }
    for (SceneMesh& mesh : mesh_jobs) {
      if (mesh.blob.length_bytes == 0 || mesh.blob.offset_bytes < begin ||
          mesh.blob.offset_bytes + mesh.blob.length_bytes > end) {
        continue;
      }
      job.meshes.push_back(mesh);
      mesh.blob.length_bytes = 0;  // taken
    }
    ++totals.reads;
    ++totals.reads_by_granularity[int(read.granularity)];
    totals.bytes_read += read.range.length_bytes;
    ++stats.reads_started;
    if (!job.parse.empty()) ++node_reads_in_flight;
    pool->submit(std::move(job));
  }
  // Every refinement's hull lies in its holder's block, which some read covers; one that
  // found no read (none expected) is released to be asked for again.
  for (const detail::LevelJob& level : refinements) {
    if (!level.tiles.empty()) levelSettled(level.texture);
  }
  for (const SceneMesh& mesh : mesh_jobs) {
    if (mesh.blob.length_bytes != 0) mesh_busy[mesh.index] = false;
  }
}

void SceneStreamer::Impl::planAndSubmit(const PerspectiveView& camera, uint64_t budget, bool moving,
                                        SceneFrameStats& stats) {
  const uint32_t pending = pool->pending();
  if (pending >= options.max_reads_in_flight) return;
  uint32_t slots = options.max_reads_in_flight - pending;
  const LinkCost cost = link();
  const std::vector<uint32_t> to_read = leavesToRead(slots * kWantsPerSlot);
  const uint32_t leaves = uint32_t(to_read.size());
  for (uint32_t leaf : to_read) {
    // The leaf and every unknown ancestor: they hold its objects' shared meshes and textures.
    for (uint32_t n = leaf;; n = parent[n]) {
      if (node_state[n] == NodeState::kUnknown && !plan[n].wanted) {
        want(n);
        if (readPrefixFirst(n, cost)) {
          plan[n].pieces.push_back({nodes[n].own.offset_bytes, prefix_bytes[n]});
        }
      }
      if (n == 0) break;
    }
  }
  // At rest, the meshes and levels of the view wait for the node reads on their way: asked for
  // together once those land, they join into few reads instead of one wave per arrival. A
  // moving camera asks at once (what it sees now may be gone when the nodes land).
  std::vector<SceneMesh> mesh_jobs;
  std::vector<detail::LevelJob> refinements;
  if (camera_changed || node_reads_in_flight == 0) {
    wantMeshes(mesh_jobs);
    refinements = addRefinements(
        budget, moving, slots - std::min(slots, (leaves + kWantsPerSlot - 1) / kWantsPerSlot));
  }
  if (!plan_touched.empty()) submitPlan(camera, refinements, mesh_jobs, stats);
  for (uint32_t n : plan_touched) {
    plan[n].wanted = false;
    plan[n].pieces.clear();
  }
  plan_touched.clear();
}

SceneFrameStats SceneStreamer::update(const PerspectiveView& camera) {
  Impl& s = *impl_;
  SceneFrameStats stats;
  s.applyResults(stats);
  const bool changed = s.first_frame || !sameCamera(camera, s.last_camera);
  s.first_frame = false;
  s.last_camera = camera;
  s.still_frames = changed ? 0 : s.still_frames + 1;
  s.camera_changed = changed;
  stats.moving = s.still_frames < s.options.still_after_frames;
  const uint64_t budget =
      stats.moving ? s.options.moving_texel_budget_bytes : s.options.still_texel_budget_bytes;
  const detail::Frustum frustum = detail::frustumOf(camera);
  s.queryVisible(frustum);
  stats.visible_leaves = uint32_t(s.visible_leaves.size());
  s.collectDemands(camera, frustum, budget, stats);
  s.evict(budget, stats);
  s.planAndSubmit(camera, budget, stats.moving, stats);
  for (uint32_t o : s.drawable) {
    for (uint32_t t : s.objects[o].textures) {
      if (t != kNoTexture && t < s.coarsest_known.size() && !s.coarsest_known[t]) {
        ++stats.untextured_objects;
        break;
      }
    }
  }
  stats.texel_bytes = s.residency.budgetedBytes();
  stats.texel_budget_bytes = budget;
  stats.pinned_texel_bytes = s.residency.pinnedBytes();
  return stats;
}

const std::vector<uint32_t>& SceneStreamer::drawableObjects() const {
  return impl_->drawable;
}

const SceneObject* SceneStreamer::object(uint32_t index) const {
  return index < impl_->objects.size() && impl_->object_known[index] ? &impl_->objects[index]
                                                                     : nullptr;
}

const MeshData* SceneStreamer::mesh(uint32_t index) const {
  return index < impl_->meshes.size() ? impl_->meshes[index].get() : nullptr;
}

uint32_t SceneStreamer::residentLevel(uint32_t texture) const {
  return impl_->residency.resident(texture);
}

uint32_t SceneStreamer::wantedLevel(uint32_t texture) const {
  return impl_->residency.wanted(texture);
}

const std::vector<Image>* SceneStreamer::levelTiles(uint32_t texture, uint32_t level) const {
  const Impl& s = *impl_;
  if (texture >= s.levels.size() || level < s.residency.resident(texture) ||
      level > s.residency.coarsest(texture)) {
    return nullptr;
  }
  if (level == s.residency.coarsest(texture)) return nullptr;  // one tile: coarsestTile
  return &s.levels[texture][level];
}

const Image* SceneStreamer::coarsestTile(uint32_t texture) const {
  const Impl& s = *impl_;
  return texture < s.coarsest_known.size() && s.coarsest_known[texture] ? &s.coarsest[texture]
                                                                        : nullptr;
}

const SceneStreamTotals& SceneStreamer::totals() const {
  return impl_->totals;
}

void SceneStreamer::waitForReads() {
  impl_->pool->waitIdle();
}

}  // namespace tessera
