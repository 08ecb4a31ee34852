#pragma once
/// \file
/// The streaming runtime (docs/runtime.md): clip-region residency (Backes et al., sections
/// 5-6, with the refinements of Luo & Duan, sections 3.3-3.4), the loader pool and
/// `TileStreamer`, the facade a renderer calls once per frame. Nothing here blocks the render
/// thread: it only polls finished work. Views are those of tessera/view.h.

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <tessera/archive.h>
#include <tessera/cache.h>
#include <tessera/format.h>
#include <tessera/result.h>
#include <tessera/view.h>

namespace tessera {

/// A block of tiles at one level: [x0, x1) x [y0, y1).
struct TileRect {
  int64_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  bool contains(int64_t x, int64_t y) const { return x >= x0 && x < x1 && y >= y0 && y < y1; }
  bool empty() const { return x1 <= x0 || y1 <= y0; }
  int64_t count() const { return empty() ? 0 : (x1 - x0) * (y1 - y0); }
  friend bool operator==(const TileRect&, const TileRect&) = default;
};

/// Clip-region side in tiles for a screen: n = ceil(max(sw, sh) / t) * 2 (Backes et al., eq. 3).
uint32_t clipRegionTiles(uint32_t screen_w, uint32_t screen_h, uint32_t tile_size_px);
/// Clip-region centre tile for a view centre f in level pixels: c = floor(f / t) (eq. 4).
int64_t clipCentreTile(double f_level_px, uint32_t tile_size_px);
/// The clip region of side n around centre c: tiles [c - n/2, c - n/2 + n).
TileRect clipRegionAround(int64_t centre_x, int64_t centre_y, uint32_t n);
/// The level whose texels are at least as dense as the screen's pixels: the largest L with
/// 2^L <= texels_per_pixel, clamped to [0, level_count - 1]. This is the exact texel-to-pixel
/// form of Backes et al., eq. 5 (no magnification of a coarser level while a finer one exists).
uint32_t desiredLevelFor(double texels_per_pixel, uint32_t level_count);
/// The coarsest level at which one tile covers a clip region of n tiles at `level`:
/// level + log2(n) (Backes et al., eq. 7, with level 0 the finest), clamped to the coarsest.
uint32_t startLevelFor(uint32_t level, uint32_t n, uint32_t level_count);

/// Life cycle of a tile in the runtime (Luo & Duan, section 3.2, extended).
enum class TileState : uint8_t {
  kUnloaded,   ///< not in host memory
  kRequested,  ///< queued or being read and decoded
  kLoaded,     ///< decoded, in the host cache
  kResident,   ///< uploaded to the GPU (or the renderer's stand-in)
  kLocked,     ///< resident and never evicted (the coarsest level)
};

/// A tile the residency manager wants loaded. Lower `priority` loads sooner.
struct TileRequest {
  TileId id;
  double priority = 0;
  bool prefetch = false;  ///< wanted for a predicted move, not the current view
  /// 0 the coarsest level, 1 on screen, 2 the rest of the clip regions, 3 prefetch. The loader
  /// merges reads only within a class, so tiles on screen never wait behind the region's.
  uint32_t urgency = 0;
};

/// The upload budget that follows the measured cost of uploads (docs/runtime.md, "Upload
/// budget"): the renderer reports the render-thread time its uploads took
/// (`ApplyResult::upload_ms`), the streamer smooths bytes per millisecond over the frames that
/// uploaded, and each frame may hand over what takes `upload_share` of `frame_ms` at that
/// rate, clamped to [min_bytes, max_bytes]. A software renderer gets a few MiB a frame, a GPU
/// the maximum.
struct AdaptiveUploadOptions {
  /// Off: `ResidencyOptions::upload_budget_bytes` is the fixed budget.
  bool enabled = true;
  /// The frame-time target, ms (60 fps unless the application says otherwise).
  double frame_ms = 1000.0 / 60;
  /// Share of the frame the renderer's uploads may take, in [0, 1].
  double upload_share = 0.25;
  /// Bounds of the budget, bytes. The floor keeps a slow measurement from starving uploads
  /// (and one tile always goes up whatever the budget); the ceiling bounds what a frame can
  /// ask of the renderer's staging memory.
  uint64_t min_bytes = 1u << 20;
  uint64_t max_bytes = 32u << 20;
  /// The rate assumed before the first measurement, bytes per ms: low (256 MB/s), so the
  /// first frames never stall a slow renderer; the first measured frame replaces it.
  double initial_bytes_per_ms = 256 << 10;
  /// Weight of a new frame in the smoothed bytes and milliseconds, in (0, 1].
  double smoothing = 0.25;
};

/// Per-frame tuning. Defaults suit a 1920x1080 view with 256-px tiles.
struct ResidencyOptions {
  /// Texel bytes handed to the renderer per frame (0 = no byte limit): the upload bandwidth
  /// the runtime may ask of the renderer (16 MiB is 1 GB/s at 60 fps). Bytes, not tiles,
  /// because what an upload costs (bus bandwidth, a copy on a software renderer) grows with
  /// its bytes. Sized so that the fastest pan the runtime targets stays at full detail; a
  /// renderer that cannot take as much sets it lower, and full detail then waits a few frames
  /// longer while the view moves fast (docs/runtime.md, "Residency", step 5).
  uint64_t upload_budget_bytes = 16u << 20;
  /// Whether the byte budget follows the measured cost of uploads instead (the default);
  /// `upload_budget_bytes` is then unused.
  AdaptiveUploadOptions adaptive_upload;
  /// Tiles handed to the renderer per frame: a cap on per-tile work for small tiles.
  uint32_t upload_budget_tiles = 128;
  bool prefetch = true;  ///< direction-based prefetch (Luo & Duan, section 3.3)
  /// Largest clip-centre move per frame, in tiles of the desired level (Luo & Duan's
  /// Maxdu/Maxdv): a very fast camera streams what it can show instead of what it flew over.
  double max_centre_step_tiles = 4;
  /// Tiles kept around each clip region before eviction (the expanded region of section 3.4).
  uint32_t keep_margin_tiles = 2;
  /// While the view moves, the tiles it will show this many frames ahead at its current
  /// velocity are wanted as urgently as those it shows (0 = off). A fast pan then finds the
  /// tiles entering the screen loaded; the clip region, which follows the view with
  /// hysteresis, can trail it by half its size.
  uint32_t lookahead_frames = 6;
};

/// The most tiles of `info` a TileStreamer with `options` keeps resident for a viewport of
/// `viewport_w` x `viewport_h` px: per level, the clip region (eq. 3) with its keep margin on
/// each side, or the whole level when smaller (FrameUpdate::resident_tiles_bound). A renderer
/// sized from it before the first frame allocates no texture storage during a flight at that
/// viewport. Thread-safe.
uint64_t residentTilesBound(const ImageInfo& info, uint32_t viewport_w, uint32_t viewport_h,
                            const ResidencyOptions& options);

/// What a frame looked like: the figures `tessera fly` records.
struct FrameReport {
  uint32_t desired_level = 0;
  uint32_t finest_full_level = 0;  ///< finest level whose resident tiles cover the whole view
  double coverage_desired = 0;     ///< fraction of visible texture covered at the desired level
  bool fully_covered = false;      ///< every visible texel covered by some resident level
  size_t queue_length = 0;         ///< requests waiting in the loader
  size_t in_flight = 0;
  /// When the loader last ran out of work (queue and in-flight both emptied): with both 0,
  /// the moment loading finished, which a frame only sees at its next update.
  std::chrono::steady_clock::time_point loader_idle_since{};
  size_t uploads = 0;  ///< tiles handed to the renderer this frame
  uint64_t upload_bytes = 0;
  /// The byte budget this frame's uploads were chosen within (0: no byte limit), and the
  /// smoothed upload rate it came from (bytes per render-thread ms; 0 with a fixed budget).
  uint64_t upload_budget_bytes = 0;
  double upload_bytes_per_ms = 0;
  uint64_t bytes_read_total = 0;     ///< by the loader since start, merged-read gaps included
  uint64_t payload_bytes_total = 0;  ///< payload bytes of the tiles those reads delivered
  uint64_t reads_total = 0;          ///< read calls on the byte source
  uint64_t tiles_loaded_total = 0;
  uint64_t load_failures_total = 0;
  double decode_ms_total = 0;  ///< worker time spent decoding since start
  /// Of decode_ms_total, the time spent encoding JPEG tiles to bc1
  /// (StreamerOptions::transcode_to_bc1), and the delivered tiles so encoded.
  double transcode_ms_total = 0;
  uint64_t tiles_transcoded_total = 0;
  uint64_t hinted_bytes_total = 0;  ///< bytes the byte source was told to fetch ahead
  double update_ms = 0;             ///< render-thread time of this update() call

  // The link as the loader measures it (every source, adaptive or not; docs/runtime.md).
  double link_bytes_per_s = 0;         ///< throughput estimate, 0 before the first read
  double link_latency_ms = 0;          ///< latency estimate (request to first byte)
  double queue_wait_ms = 0;            ///< recent tiles' wait from request to read
  uint64_t cancelled_total = 0;        ///< queued requests dropped as no longer wanted
  uint64_t reads_cancelled_total = 0;  ///< reads abandoned in flight (every tile left the view)
  /// Dependent codecs (ptm; docs/runtime.md, "Dependent codecs"): parents the loader queued
  /// itself for wanted children, and children whose parent had left the cache by their decode
  /// (the parent chain was read again in the same job; its bytes are in bytes_read_total),
  /// and children whose payload was read while their parent loaded (decoded after it).
  uint64_t parents_queued_total = 0;
  uint64_t parent_fallbacks_total = 0;
  uint64_t children_read_early_total = 0;
  /// LoaderPriority::kAuto: times the normal-priority helpers began loading because the
  /// idle-priority loader threads got no core, and the batches they loaded.
  uint64_t loader_rescues_total = 0;
  uint64_t rescued_batches_total = 0;

  // Adaptive scheduling (StreamerOptions::adaptive; Marvie & Bouatouch, part III).
  bool adaptive = false;    ///< the adaptive policy chose this frame's requests
  bool view_still = false;  ///< still budgets: the view has not changed for still_after_s
  /// Finest level requested this frame (coarser ones too); desired_level when not adaptive.
  uint32_t requested_level = 0;
  /// Payload bytes that can arrive within this mode's per-level time limit at the estimate.
  uint64_t budget_bytes = 0;
  uint64_t memory_budget_bytes = 0;  ///< this mode's client-memory budget
  uint64_t memory_bytes = 0;         ///< decoded bytes of the wanted tiles held or requested
  uint64_t requested_bytes = 0;      ///< payload bytes requested and not yet arrived
  uint64_t deferred_tiles = 0;       ///< wanted tiles not requested (beyond the budgets)
  /// Egress over the flight so far (AdaptiveOptions::egress, which says what is counted):
  /// payload bytes and tiles the views needed and those requested beyond them; and the tiles
  /// this frame held back by the budget.
  uint64_t view_bytes_total = 0;
  uint64_t view_tiles_total = 0;
  uint64_t prefetch_bytes_total = 0;
  uint64_t prefetch_tiles_total = 0;
  uint64_t egress_deferred_tiles = 0;
};

/// A load that failed (a read, a checksum, a decode): the loader retries it after a backoff
/// while the tile is wanted, so one tile may fail many times.
struct LoadFailure {
  TileId id;
  ErrorCode code = ErrorCode::kIo;
  /// Names the archive, the tile and the problem; for a URL, the server's status and reason
  /// ("http://h/s.tess: tile (0,3,7): bytes=81234-93000: HTTP 503 Service Unavailable (after
  /// 4 attempts)").
  std::string message;
};

/// What the renderer should do this frame.
struct FrameUpdate {
  /// Tiles to upload now, parents before children, within the upload budget. Each is in
  /// the cache and pinned until `TileStreamer::acknowledge` hears whether the renderer
  /// accepted or declined it.
  std::vector<std::shared_ptr<const DecodedTile>> uploads;
  /// Resident tiles the renderer may drop (left every region).
  std::vector<TileId> releases;
  /// Per level, the tiles the view needs now (clip regions clipped to the image).
  struct LevelRegion {
    uint32_t level = 0;
    TileRect region;
  };
  std::vector<LevelRegion> regions;
  /// n of Backes et al., eq. 3, for this frame's viewport: the side of an unclipped clip
  /// region in tiles (a clipmap sizes its level layers by it).
  uint32_t clip_region_tiles = 0;
  /// The most tiles of this image the streamer keeps resident at this viewport: per level,
  /// the clip region with its keep margin (or the whole level when smaller). Lookahead and
  /// far perspective ground can exceed it for a while; a renderer sizes its texture storage
  /// from it up front and grows only past it.
  uint64_t resident_tiles_bound = 0;
  /// True when this update recomputed the residency plan (clip regions, wanted tiles and their
  /// priorities); false when the view and everything the plan depends on were as in the last
  /// update, which reused that plan.
  bool replanned = false;
  FrameReport report;
  /// Loads that failed since the last update, in the order they failed
  /// (FrameReport::load_failures_total counts them all).
  std::vector<LoadFailure> failures;
};

/// A renderer's answer to a FrameUpdate (`Renderer::apply`), for `TileStreamer::acknowledge`.
/// Every tile of `FrameUpdate::uploads` is in exactly one of `accepted` and `declined`.
struct ApplyResult {
  std::vector<TileId> accepted;  ///< uploaded: resident from now on
  /// Not taken (no room, or not this image's): still loaded, offered again in a later frame.
  std::vector<TileId> declined;
  /// Tiles resident before this frame that the renderer gave up on its own (a clipmap slot
  /// taken by a tile of the clip region, its layers reallocated): offered again from the
  /// cache while they are wanted.
  std::vector<TileId> dropped;
  /// Render-thread milliseconds the accepted uploads took (staging copy and texture updates),
  /// for the adaptive upload budget; negative when not measured (no sample is taken).
  double upload_ms = -1;
};

/// Budgets for one mode of adaptive scheduling.
struct AdaptiveBudget {
  /// Decoded bytes of the wanted tiles held or requested; 0 = the cache budget, which is the
  /// ceiling in any case. Limits what is requested; held tiles cost no transfer and stay
  /// until the cache evicts them.
  uint64_t memory_bytes = 0;
  /// Seconds within which a level's missing tiles must be able to arrive at the estimated
  /// throughput and latency for that level to be requested (0 = no limit). Levels are taken
  /// coarse to fine and the first that does not fit ends the refinement.
  double level_time_limit_s = 0;
};

/// What adaptive scheduling may spend beyond the view (docs/remote.md, "Egress"): the rest of
/// the clip regions and the prefetch ring (urgency 2-3) cost bytes and requests that a metered
/// link, a phone or a CDN billed per byte and per request pays for. Counted over the
/// streamer's life (a flight), each tile once: the view's own tiles (urgency 0-1, every level
/// the residency wants, full detail included) once their payload size is known (their
/// directory entry read), whether fetched or already held; those beyond the view when first
/// requested. The view's tiles are never limited.
/// Prefetch also waits, as before, until the view's tiles have arrived and while its bytes on the
/// way fit what the measured link delivers in the time limit, so a slow link prefetches later and
/// less.
struct EgressBudget {
  /// The flight's bytes are at most this many times the bytes of the view's own tiles: what
  /// goes beyond the view is at most (byte_factor - 1) times them. 1 or less: nothing beyond
  /// the view; 0: no bound from the view's bytes.
  double byte_factor = 1.5;
  /// The same for requests, counted one per tile requested (the coalescing of reads makes
  /// fewer, so this bounds them from above). 0: no bound.
  double request_factor = 1.5;
  /// Absolute caps on what goes beyond the view over the flight; 0: none.
  uint64_t max_prefetch_bytes = 0;
  uint64_t max_prefetch_requests = 0;

  /// Only the view: for metered links (`--egress metered`).
  static EgressBudget metered() { return {1.0, 1.0, 0, 0}; }
  /// No bound but the link's time and the memory budgets (`--egress unbounded`).
  static EgressBudget unbounded() { return {0, 0, 0, 0}; }
};

/// Adaptive scheduling (Marvie & Bouatouch, "Remote Rendering of Massively Textured 3D
/// Scenes Through Progressive Texture Maps", part III): from the loader's throughput and
/// latency estimates, request only the levels whose tiles can arrive within a time limit and
/// fit a memory budget, coarse first; one set of budgets while the view moves and a wider one
/// once it has been still for `still_after_s` (the paper's n seconds), when refinement
/// proceeds. Off by default: over a local disk every level fits and the policy only costs
/// render-thread time (docs/runtime.md has the figures); `tessera fly --link` turns it on.
struct AdaptiveOptions {
  bool enabled = false;
  double still_after_s = 1.0;
  AdaptiveBudget moving{size_t(256) << 20, 2.0};
  AdaptiveBudget still{0, 30.0};
  /// Throughput assumed until the first read is measured; 0: request only the coarsest level
  /// until then (one round trip on a remote link, a frame on a local disk).
  double assumed_bytes_per_s = 0;
  /// Bytes and requests beyond the view over a flight.
  EgressBudget egress;
  /// The time source for the still/moving switch; tests inject one. Empty: steady_clock.
  std::function<std::chrono::steady_clock::time_point()> clock;
};

/// How loader threads share the CPU with the render thread and the rest of the machine
/// (docs/runtime.md, "Loader priority").
enum class LoaderPriority : uint8_t {
  /// The default: loader threads under SCHED_IDLE, which give way at once to any thread of
  /// normal priority, the render thread first; and as many helper threads of normal priority
  /// as cores (at most the loader threads), which sleep until ready work has waited 16 ms with
  /// no idle-priority thread taking any, and then load until nothing is ready. On a free
  /// machine the helpers never run; when other programs keep every core busy, where idle
  /// threads would starve, the helpers load at their fair share of the cores.
  kAuto,
  /// Every loader thread under SCHED_IDLE, no helpers: a decode never delays a normal thread,
  /// and nothing loads while other threads keep every core busy.
  kIdle,
  /// Every loader thread at niceness 5.
  kNice,
};

/// Everything `TileStreamer::create` can set.
struct StreamerOptions {
  size_t cache_budget_bytes = size_t(512) << 20;
  bool viewer_shift_eviction = true;  ///< else LRU
  uint32_t loader_threads = 0;        ///< 0 = all cores
  /// The loader threads' scheduling (LoaderPriority): by default idle-priority threads, so a
  /// frame never waits for a decode, with normal-priority help when they starve.
  LoaderPriority loader_priority = LoaderPriority::kAuto;
  /// Tile buffers kept idle for the next decodes: those of evicted tiles, and fresh ones the
  /// loaders fault in while they have nothing to do (only into room the cache budget still
  /// has), so the tiles after a jump skip the page faults of fresh memory (docs/runtime.md).
  uint64_t recycled_buffer_bytes = 64u << 20;
  ResidencyOptions residency;
  /// A loader thread takes queued tiles of one level and urgency whose payloads follow each
  /// other in the file with gaps under this, and decodes them as one batch: neighbours on
  /// screen are neighbours in the Hilbert layout, and a batch pays the per-job costs (queue,
  /// lock, read call) once (docs/runtime.md, "Loader pool").
  uint64_t batch_gap_bytes = 64 * 1024;
  /// Within a batch, payloads closer than this are read in one read, gap included: the gaps
  /// are bytes read for nothing, each extra read a system call, and this is where the two
  /// balance on a local disk (docs/runtime.md). A remote source, where each read is a
  /// request, wants it as large as batch_gap_bytes.
  uint64_t merge_gap_bytes = 16 * 1024;
  /// Payload bytes at the head of the loader's queue the byte source is told to fetch ahead
  /// (ByteSource::prefetch), topped up each time a loader thread takes work. A cold disk then
  /// has many reads in flight instead of one per thread (docs/runtime.md); 0 = off.
  uint64_t read_ahead_bytes = 4u << 20;
  /// The most bytes a batch spans in the file; 0 makes every tile its own read and batch.
  uint64_t max_merged_read_bytes = 4 << 20;
  /// Batches and merged reads sized by the measured link (docs/remote.md, "Fewer requests";
  /// tuneForRemoteSource turns it on). Once a round trip carries more than a tile's worth of
  /// bytes (bandwidth x latency over 16 KiB), a request costs more than the bytes around it:
  /// a batch then takes every queued neighbour of its level and urgency instead of a fair
  /// share per thread (within max_merged_read_bytes), and both gaps grow to
  /// `gap_round_trip_share` of a round trip's bytes, at most `max_link_gap_bytes` (never
  /// below batch_gap_bytes and merge_gap_bytes). Until the first read is measured, and on a
  /// fast local link, the fixed values apply.
  bool link_sized_reads = false;
  double gap_round_trip_share = 0.25;
  uint64_t max_link_gap_bytes = 256u << 10;
  /// Retry a failed read or checksum after this, doubling per failure up to the maximum.
  std::chrono::milliseconds retry_initial{10};
  std::chrono::milliseconds retry_max{1000};
  AdaptiveOptions adaptive;
  /// bc1 and bc7 tiles with a payload are handed over as stored (`DecodedTile::blocks`, no CPU
  /// decode) instead of decoded. Set it only for a renderer whose `takesStoredBlocks()` is
  /// true: any other declines such tiles. Uniform tiles are decoded either way.
  bool keep_block_compressed = false;
  /// JPEG tiles of 8-bit grey or RGB, once decoded on a loader thread, are encoded to bc1 by
  /// Tessera's fast encoder (docs/codecs.md, "Fast bc1 transcoder") and handed over as blocks,
  /// as a bc1 archive's tiles are: an eighth of RGBA's upload and GPU bytes, at the fast
  /// encoder's error. Uniform tiles, tiles with alpha and other codecs stay decoded. As with
  /// keep_block_compressed, set it only for a renderer whose `takesStoredBlocks()` is true
  /// (and created with RendererOptions::transcode_to_bc1, docs/rendering.md).
  bool transcode_to_bc1 = false;
};

/// Turns `options` into what a source whose every read is a network round trip wants (an
/// HTTP URL, a simulated link); tools then apply what the user set explicitly
/// (docs/runtime.md, "Loader settings over a network"):
/// - `kRemoteLoaderThreads` loader threads at least: each waits a round trip per read, so
///   the reads in flight, not the cores, set the rate;
/// - one read per batch (batch gap = merge gap = 16 KiB): a batch's runs are read one after
///   another, each a round trip, and bytes in the gaps cost link time;
/// - no read-ahead: the loaders' parallel reads keep the link busy, and fetched-ahead tiles
///   that adaptive scheduling then drops cost link time the view needed;
/// - adaptive scheduling (Marvie & Bouatouch, part III), with its egress budget;
/// - batches and gaps sized by the measured link (link_sized_reads).
void tuneForRemoteSource(StreamerOptions& options);

/// An egress budget from its command-line spelling (`tessera fly|view --egress`): `default`
/// (1.5 times the view's bytes and requests), `metered` (only the view), `unbounded`, or a
/// factor >= 1 for both bytes and requests (`2.5`). kInvalidArgument otherwise.
[[nodiscard]] Result<EgressBudget> parseEgressBudget(const std::string& spec);
/// Loader threads tuneForRemoteSource asks for (more if the machine has more cores); the HTTP
/// source's default connection count matches it.
inline constexpr uint32_t kRemoteLoaderThreads = 16;

/// The runtime for one archive. Render thread only, except where a method says otherwise:
/// `update` and `acknowledge` never wait on disk, network or decoding; loading happens on the
/// loader threads it owns.
class TileStreamer {
 public:
  /// Starts the loader threads over `archive`. Fails (kInvalidArgument) for a null archive or a
  /// cache budget below 64 of its largest tiles (the coarsest levels are pinned and a few
  /// tiles are always in flight: less could never make progress).
  [[nodiscard]] static Result<std::unique_ptr<TileStreamer>> create(
      std::shared_ptr<Archive> archive, const StreamerOptions& options);
  ~TileStreamer();
  TileStreamer(const TileStreamer&) = delete;
  TileStreamer& operator=(const TileStreamer&) = delete;

  /// Once per frame: drains finished loads, recomputes clip regions and priorities for
  /// `view`, cancels requests that left every region, and returns the uploads for this frame
  /// (valid until the next update). A view of an image the archive lacks shows its last one.
  const FrameUpdate& update(const View& view);
  /// The renderer's answer to the last FrameUpdate, once per apply and before the next
  /// update: accepted tiles become resident and their cache pins are released; declined ones
  /// are unpinned and offered again in a later frame; dropped ones stop being resident and are
  /// offered again from the cache while wanted. Tiles it does not know are ignored.
  void acknowledge(const ApplyResult& result);
  /// Current state of a tile.
  TileState state(const TileId& id) const;
  /// Blocks until the loader is idle: for tests and benchmarks, never the render thread. Any
  /// thread.
  void waitIdleForTesting();

  /// The archive it streams. Any thread (the archive is thread-safe).
  const Archive& archive() const;
  /// The decoded-tile cache the loaders fill. Any thread (the cache is thread-safe).
  TileCache& cache();
  /// A snapshot of the cache's counters. Any thread.
  CacheStats cacheStats() const;

 private:
  struct Impl;
  explicit TileStreamer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace tessera
