#pragma once
/// \file
/// Streaming a scene archive (docs/scenes.md, "Streaming"): reads at variable I/O granularity
/// (Zhou, Zhu & Zhang, seed 004: one object, one node or one whole subtree per read, chosen by
/// a cost model of the source) and per-object texture levels under a texel budget (Marvie &
/// Bouatouch, seed 003 part III: moving and still budgets). The render thread calls
/// SceneStreamer::update once per frame; it never waits on disk, network or decoding.

#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include <tessera/byte_source.h>
#include <tessera/coverage_hints.h>
#include <tessera/result.h>
#include <tessera/scene.h>
#include <tessera/view.h>

namespace tessera {

/// The cost model of a source: a read of b bytes costs latency_s + b / bandwidth.
struct LinkCost {
  double latency_s = 0.0002;               ///< per read: seek or round trip; >= 0
  double bandwidth_bytes_per_s = 500.0e6;  ///< sustained; > 0
};

/// The link cost of `source`: measured from its latest request samples (ByteSource::linkStats:
/// median first-byte time as latency; bytes over transfer time as bandwidth, or the fallback's
/// when the transfers were too short to time) when it has any, else `fallback` (a local file
/// has none). Thread-safe.
LinkCost measureLinkCost(const ByteSource& source, const LinkCost& fallback = {});

/// How much one read fetches (seed 004, section 4).
enum class ReadGranularity : uint8_t {
  /// Pieces of one node: mesh blobs and texture levels once its head is known, or the head and
  /// directory pages of a large node not yet read (neighbouring pieces join into one read).
  kObject = 0,
  kNode = 1,     ///< one node's block: head, geometry and texture levels together
  kSubtree = 2,  ///< a node's subtree: every block under it, one contiguous range
};
const char* readGranularityName(ReadGranularity granularity);

/// One read of a plan: exactly one ByteSource::read of `range`.
struct PlannedRead {
  ReadGranularity granularity = ReadGranularity::kNode;
  uint32_t node = 0;  ///< the node whose block, subtree or piece this is
  FileRange range;
};

/// Settings of a SceneStreamer. Budgets count decoded texels (4 bytes each, whatever the
/// channels) of every level finer than a texture's coarsest; the coarsest levels are pinned
/// outside the budget so that no visible object is drawn untextured.
struct SceneStreamOptions {
  uint64_t moving_texel_budget_bytes = 64ull << 20;  ///< while the camera moves
  uint64_t still_texel_budget_bytes = 256ull << 20;  ///< after still_after_frames still frames
  uint32_t still_after_frames = 30;
  /// A level is requested only when its read (readCost under the link) takes at most this
  /// long: seed 003's per-level download time limits, short while moving.
  double moving_level_time_limit_s = 0.1;
  double still_level_time_limit_s = 10;
  uint32_t worker_threads = 2;       ///< fixed pool; >= 1
  uint32_t max_reads_in_flight = 8;  ///< reads queued or running at once
  /// Added to every wanted level (positive: coarser). Level 0 is the finest.
  double lod_bias = 0;
  /// The source's cost model; unset: measureLinkCost at every plan.
  std::optional<LinkCost> link;
  /// Average coverage hints (Marvie & Bouatouch, seed 003 part II; docs/scenes.md, "Coverage
  /// hints"): when the archive has them, open reads them (one read) and every frame the hints
  /// of the camera's cell rank leaf reads and texture loads and set the levels of textures
  /// whose users have not arrived yet; false: the projected-size estimate alone.
  bool use_coverage_hints = true;
  /// Hints to use instead of the archive's (for instance computed for another grid); they must
  /// be for this scene's textures. Null: the archive's.
  std::shared_ptr<const CoverageHints> coverage_hints;
};

/// What one update did and saw.
struct SceneFrameStats {
  uint32_t visible_leaves = 0;      ///< leaves whose box meets the view frustum
  uint32_t visible_objects = 0;     ///< objects of loaded visible leaves inside the frustum
  uint32_t waiting_leaves = 0;      ///< visible leaves whose block has not arrived yet
  uint32_t untextured_objects = 0;  ///< visible objects with a texture not resident: always 0
  uint32_t reads_started = 0;       ///< reads handed to the workers this frame
  uint32_t results_applied = 0;     ///< finished reads picked up this frame
  uint32_t levels_evicted = 0;
  uint64_t missing_pixels = 0;  ///< screen pixels of visible objects below their wanted level
  uint64_t texel_bytes = 0;     ///< budgeted texels resident after this update
  uint64_t texel_budget_bytes = 0;
  uint64_t pinned_texel_bytes = 0;  ///< coarsest levels, outside the budget
  bool moving = false;
  /// The camera's cell had coverage hints this frame, and how many textures they asked for
  /// before any of their users had arrived.
  bool hinted = false;
  uint32_t hint_only_textures = 0;
};

/// Totals since open, for reports and tests.
struct SceneStreamTotals {
  uint64_t reads = 0;  ///< ByteSource reads issued by the streamer after open
  uint64_t bytes_read = 0;
  uint64_t reads_by_granularity[3] = {0, 0, 0};  ///< indexed by ReadGranularity
  uint64_t read_errors = 0;
};

/// Streams one scene archive's geometry and texture levels for a moving perspective camera.
/// World coordinates are the camera's frame (PerspectiveView: x, y, z with z up for yaw and
/// pitch; eye_x/y/z in world units). Render thread only: every method but open must be called
/// from one thread; loads run on an internal fixed pool of worker threads.
class SceneStreamer {
 public:
  /// Reads the node table, the texture table and the coarse block (three reads, blocking:
  /// call it before the first frame), and the coverage hints when used (a fourth, unless in the
  /// header region: they are small, about 4 bytes per (cell, texture) seen, so loading them
  /// all at open keeps the workers and the frame free of them), and starts the workers. Errors
  /// name the archive (a corrupt hints block included).
  [[nodiscard]] static Result<std::unique_ptr<SceneStreamer>> open(
      std::shared_ptr<const SceneArchive> archive, const SceneStreamOptions& options = {});
  ~SceneStreamer();  ///< cancels queued reads and joins the workers
  SceneStreamer(const SceneStreamer&) = delete;
  SceneStreamer& operator=(const SceneStreamer&) = delete;

  /// One frame: picks up finished reads without waiting, finds the visible objects (R-tree
  /// query), sets each visible texture's wanted level, plans and queues reads, evicts to the
  /// budget. Never blocks on I/O or decoding.
  SceneFrameStats update(const PerspectiveView& camera);

  /// Objects visible at the last update whose geometry and every texture (at least its
  /// coarsest level) are resident: what a renderer draws.
  const std::vector<uint32_t>& drawableObjects() const;
  /// An object's record once its leaf's block has arrived, else nullptr.
  const SceneObject* object(uint32_t index) const;
  /// Decoded geometry of a mesh once its node's block has arrived, else nullptr.
  const MeshData* mesh(uint32_t index) const;
  /// The finest resident level of a texture (every coarser one is resident too).
  uint32_t residentLevel(uint32_t texture) const;
  /// The level the last update wanted for a texture (its coarsest when not visible).
  uint32_t wantedLevel(uint32_t texture) const;
  /// A resident level's decoded tiles, row-major (stored tiles, borders included); nullptr
  /// when that level is not resident, and for the coarsest level (see coarsestTile).
  const std::vector<Image>* levelTiles(uint32_t texture, uint32_t level) const;
  /// The coarsest level's one stored tile, once an object using the texture has arrived
  /// (pinned from then on), else nullptr.
  const Image* coarsestTile(uint32_t texture) const;
  const SceneStreamTotals& totals() const;

  /// Blocks until every queued and running read has finished (their results are picked up by
  /// the next update). For tests and tools that step frames; never call it on a render loop.
  void waitForReads();

  struct Impl;

 private:
  explicit SceneStreamer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace tessera
