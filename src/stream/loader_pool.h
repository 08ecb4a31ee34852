#pragma once
// The loader pool: a fixed set of worker threads fed by a priority queue that the render
// thread replaces every frame (Backes et al., section 6). Workers read (merging requests whose
// payloads are adjacent in the file into one read), verify checksums, decode and insert into
// the tile cache; the render thread polls their results and never waits for them.

#include <sys/types.h>

#include <atomic>
#include <chrono>
#include <functional>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <thread>
#include <unordered_map>
#include <optional>
#include <unordered_set>
#include <vector>

#include <tessera/archive.h>
#include <tessera/cache.h>
#include <tessera/stream.h>

#include "link_estimator.h"
#include "texel_pool.h"

namespace tessera::detail {

struct LoaderOptions {
  uint32_t threads = 0;                  ///< 0 = all cores
  uint64_t batch_gap_bytes = 64 * 1024;  ///< StreamerOptions::batch_gap_bytes
  uint64_t merge_gap_bytes = 16 * 1024;  ///< StreamerOptions::merge_gap_bytes
  uint64_t max_merged_read_bytes = 4 << 20;
  /// StreamerOptions::link_sized_reads and its two settings.
  bool link_sized_reads = false;
  double gap_round_trip_share = 0.25;
  uint64_t max_link_gap_bytes = 256u << 10;
  std::chrono::milliseconds retry_initial{10};
  std::chrono::milliseconds retry_max{1000};
  LoaderPriority priority = LoaderPriority::kAuto;  ///< StreamerOptions::loader_priority
  /// StreamerOptions::recycled_buffer_bytes.
  uint64_t recycled_bytes = 64u << 20;
  /// StreamerOptions::read_ahead_bytes.
  uint64_t read_ahead_bytes = 4u << 20;
  /// StreamerOptions::keep_block_compressed.
  bool keep_block_compressed = false;
  /// StreamerOptions::transcode_to_bc1.
  bool transcode_to_bc1 = false;
};

/// A thread's scheduling figures from /proc's schedstat: nanoseconds on a core, and waiting
/// on a run queue for one (the kernel adds a wait only when it ends, so a thread that never
/// gets a core shows none). Negative where /proc does not say.
struct ThreadTimes {
  int64_t on_cpu_ns = -1;
  int64_t waited_ns = -1;
};

/// A finished request, reported once to the render thread.
struct LoadEvent {
  TileId id;
  bool ok = false;
  bool stale = false;      ///< decoded but no longer wanted: dropped, not cached
  std::string error;       ///< names the archive, the tile and the problem
  bool cancelled = false;  ///< its read was abandoned in flight (also stale): not a failure
  ErrorCode code = ErrorCode::kIo;  ///< a failure's kind (neither ok nor stale)
};

struct LoaderStats {
  uint64_t bytes_read = 0;     ///< including gaps read inside merged ranges
  uint64_t payload_bytes = 0;  ///< payload bytes of tiles delivered
  uint64_t reads = 0;          ///< ranges read from the byte source (merged runs)
  uint64_t tiles_loaded = 0;
  uint64_t failures = 0;
  uint64_t cancelled = 0;      ///< queued requests dropped because no longer wanted
  uint64_t stale_dropped = 0;  ///< finished requests dropped because no longer wanted
  uint64_t decode_ns = 0;
  /// Of decode_ns, the time spent encoding decoded JPEG tiles to bc1
  /// (LoaderOptions::transcode_to_bc1), and the tiles so encoded.
  uint64_t transcode_ns = 0;
  uint64_t tiles_transcoded = 0;
  uint64_t hinted_bytes = 0;  ///< bytes the byte source was told to fetch ahead
  /// Reads abandoned in flight through readCancellable because every tile they carried left
  /// the wanted set (their tiles are neither failures nor retried).
  uint64_t reads_cancelled = 0;
  /// Parents of a dependent codec's tiles (ptm) the loader queued itself because a wanted
  /// child's parent was neither wanted, cached nor loading (docs/runtime.md, "Dependent
  /// codecs").
  uint64_t parents_queued = 0;
  /// Children decoded after reading their parent chain in the same job, because the parent
  /// left the cache (or could not be loaded) between its load and the child's decode.
  uint64_t parent_fallbacks = 0;
  /// Tiles taken while their parent was being loaded, because no other work was ready: their
  /// payloads are read during the parent's load, and they decode after it (docs/runtime.md,
  /// "Dependent codecs").
  uint64_t children_read_early = 0;
  /// LoaderPriority::kAuto: times the normal-priority helpers began loading because the
  /// idle-priority workers starved, and the batches they loaded.
  uint64_t rescues = 0;
  uint64_t rescued_batches = 0;
  /// Of those, tiles a starving idle worker held, loaded a second time by a helper.
  uint64_t tiles_loaded_twice = 0;
  LinkEstimate link;  ///< throughput, latency and queue wait measured on every read
  /// When the queue and in-flight set last became empty together (the end of a load).
  std::chrono::steady_clock::time_point idle_since{};
  size_t queued = 0;
  size_t in_flight = 0;
};

/// Thread-safe. Lock order: the pool's mutex, then the cache's (never the reverse).
class LoaderPool {
 public:
  LoaderPool(std::shared_ptr<Archive> archive, TileCache& cache, const LoaderOptions& options);
  /// Stops the workers after their current batch; queued requests are dropped.
  ~LoaderPool();
  LoaderPool(const LoaderPool&) = delete;
  LoaderPool& operator=(const LoaderPool&) = delete;

  /// Replaces the queue with `requests` (sorted by priority, lower first). Queued requests not
  /// among them are cancelled; in-flight ones finish and are dropped if still unwanted.
  /// Tiles failing repeatedly wait out their backoff. Render thread; takes the lock briefly.
  void setWanted(std::span<const TileRequest> requests);
  /// Moves finished events into `out`. Never blocks on I/O or decoding.
  void poll(std::vector<LoadEvent>& out);
  /// The tiles being read or decoded now, taking the lock once.
  void inFlight(std::unordered_set<TileId, TileIdHash>& out) const;
  /// True when the tile is queued or being loaded.
  bool isRequested(const TileId& id) const;
  LoaderStats stats() const;
  /// The link as measured so far (without the pool's lock).
  LinkEstimate linkEstimate() const { return link_.estimate(); }

  /// What a batch may take and waste, from the options and (link_sized_reads) the link.
  struct ReadSizing {
    uint64_t batch_gap_bytes = 0;
    uint64_t merge_gap_bytes = 0;
    bool whole_class = false;  ///< take every queued neighbour, not a fair share per thread
  };
  ReadSizing readSizing() const;
  /// Idle tile buffers kept for the next decodes (recycled or prewarmed).
  uint64_t idleBufferBytes() const { return texel_pool_->idleBytes(); }
  /// Blocks until the idle workers have filled the buffer pool as far as they will (up to
  /// recycled_bytes, within the cache's free budget). Tests only: it returns when that holds,
  /// and nothing wakes it if the cache frees room later while every worker sleeps.
  void waitPrewarmed();
  /// Blocks until nothing is queued (and ready) or in flight. Tests and benchmarks only.
  void waitIdle();

 private:
  struct Pending {
    TileId id;
    double priority;
    uint32_t urgency;
  };
  struct RetryState {
    uint32_t failures = 0;
    std::chrono::steady_clock::time_point not_before;
  };
  /// A tile of a batch with its directory entry.
  struct BatchItem {
    TileId id;
    TileEntry entry;
  };
  struct Batch;
  struct BatchReads;
  /// A read in flight and the tiles it carries; setWanted sets `cancel` when none of them is
  /// wanted any more, so a read over a network stops using the link.
  struct ActiveRead {
    std::vector<TileId> tiles;
    std::atomic<bool> cancel{false};
  };
  /// True when any of `tiles` is wanted. Under mutex_.
  bool anyWantedLocked(std::span<const TileId> tiles) const;
  /// Loader thread `worker_index` (LoaderOptions::priority).
  void run(uint32_t worker_index);
  /// A normal-priority helper (LoaderPriority::kAuto): loads while the idle workers starve.
  /// Helper 0 watches them every kStarvedAfter while there is work.
  void runHelper(uint32_t helper_index);
  /// Ends a rescue: the idle workers take work again, and a new window starts. Under mutex_.
  void endRescueLocked();
  /// Records each idle worker's run-queue wait, starting a window. Under mutex_.
  void sampleIdleWaitLocked();
  /// True when the idle workers waited for a core at least half the window since the last
  /// sample (without /proc's schedstat: ready work waited kStarvedAfter and none took it);
  /// starts the next window. Under mutex_.
  bool idleWorkersStarvedLocked(std::chrono::steady_clock::time_point now);
  /// Takes, as a batch of its own, the best tile a starving idle worker has held for
  /// kStarvedAfter, of priority `up_to` or better (lower), to load it a second time. Under
  /// mutex_.
  bool takeHostageLocked(Batch& batch, std::chrono::steady_clock::time_point now, double up_to);
  /// Whether a finished load of `id` counts: false for the later of a duplicated tile's two
  /// loads, which is dropped unseen. Under mutex_.
  bool claimLocked(const TileId& id);
  /// When the best ready request (not waiting out a backoff) was first wanted; max() when
  /// nothing is ready. Under mutex_.
  std::chrono::steady_clock::time_point readySinceLocked(
      std::chrono::steady_clock::time_point now) const;
  /// Waits on `wake_up` until notified or the earliest retry backoff ends. Under mutex_.
  void sleepUntilWorkLocked(std::unique_lock<std::mutex>& lock, std::condition_variable& wake_up);
  /// Loads a batch taken under `lock`, which it releases meanwhile.
  void loadTakenBatch(std::unique_lock<std::mutex>& lock, Batch& batch, CodecScratch& scratch,
                      std::vector<TileId>& read_ahead);
  /// Takes the best ready request with the candidates it may merge with. `may_wait`: it may be
  /// a tile whose parent is loading (its worker then waits for the parent before decoding).
  bool takeBatchLocked(Batch& batch, std::chrono::steady_clock::time_point now, bool may_wait);
  /// Moves queue_[index] into `batch` (in flight) with the candidates it may merge with; an
  /// `early` batch (its tile's parent loading) may take siblings whose parent is loading too.
  void takeLocked(Batch& batch, size_t index, bool early,
                  std::chrono::steady_clock::time_point now);
  /// Reads, verifies, decodes and caches the batch's tiles, finishing each.
  void loadBatch(Batch& batch, CodecScratch& scratch);
  /// Of `neighbours` (encoded, sorted by offset), those whose payloads extend `first`'s range
  /// forwards, then backwards, with gaps of at most `gap_bytes` and the whole range at most
  /// `max_bytes` long: one read then carries them all.
  static std::vector<BatchItem> neighboursInRange(std::span<const BatchItem> neighbours,
                                                  const TileEntry& first, uint64_t gap_bytes,
                                                  uint64_t max_bytes);
  /// Adds to `batch` the candidates that extend its first tile's read (neighboursInRange) and
  /// are still queued, taking them in flight.
  void addNeighbours(Batch& batch, const TileEntry& first_entry);
  /// Reads the batch's payloads in file order, runs with gaps under merge_gap_bytes in one range
  /// each (one call each, or all in one readEach on a source that reads ranges together),
  /// counting the reads (ranges) and bytes in stats_.
  BatchReads readBatch(const Batch& batch);
  /// Reads run `index` of `reads`, cancellable through active_reads_ (setWanted abandons it
  /// when none of `tiles` is wanted any more), or skips it (kCancelled) when none is wanted now.
  void readRun(BatchReads& reads, size_t index, std::vector<TileId> tiles);
  /// Feeds the byte source's requests so far (LinkStats::recent: the archive's open) to the
  /// link estimate, so the first frame's scheduling knows the link.
  void seedLinkEstimate();
  /// Reads every run of `reads` with one ByteSource::readEach (a source that reads ranges
  /// together), each run failing alone; cancellable as one read of all of `run_tiles`.
  void readRunsTogether(BatchReads& reads, const std::vector<std::vector<TileId>>& run_tiles);
  /// The verified payload of batch item `index` (empty for a tile without one); its run's
  /// error when the read failed or was abandoned (kCancelled).
  Result<std::span<const uint8_t>> payloadOf(const BatchItem& item, const BatchReads& reads,
                                             size_t index) const;
  /// Decodes a verified payload into a cache tile after the tile's parent has loaded, inserts
  /// it if it is still wanted (dropped as stale if not) and finishes it.
  void decodeAndDeliver(const BatchItem& item, std::span<const uint8_t> payload, size_t tile_bytes,
                        CodecScratch& scratch);
  /// A bc1/bc7 payload kept as stored (LoaderOptions::keep_block_compressed): checked for its
  /// size, copied into a cache tile's blocks and delivered as decodeAndDeliver does.
  void deliverBlocks(const BatchItem& item, std::span<const uint8_t> payload);
  /// LoaderOptions::transcode_to_bc1: the blocks of a decoded opaque 8-bit JPEG tile (grey or
  /// RGB, a full stored tile) encoded by encodeBc1Fast; codec kRaw (keep the texels) for any
  /// other tile. Adds the encoding time to `transcode_ns`.
  StoredBlocks transcodeToBc1(const BatchItem& item, const Image& texels,
                              uint64_t& transcode_ns) const;
  /// The end of a load: claims the tile, counts it, hands `store` whether it is still wanted
  /// (it inserts the tile, or recycles its buffer), and finishes it.
  void deliver(const BatchItem& item, uint64_t decode_ns, const std::function<void(bool)>& store,
               std::optional<uint64_t> transcode_ns = std::nullopt);
  /// True when `id` is coded against a parent (its image's codec is dependent and it is below
  /// the coarsest level). Lock-free: reads constant members only.
  bool needsParent(const TileId& id) const;
  /// Where a tile stands towards its parent: free to load (independent, or its parent is
  /// neither loading nor ready in the queue), its parent loading, or its parent queued and
  /// ready to be taken (not waiting out a retry backoff).
  enum class ParentWait { kNone, kLoading, kQueued };
  /// ParentWait of `id`. Under mutex_, within one takeBatchLocked.
  ParentWait parentWaitLocked(const TileId& id, std::chrono::steady_clock::time_point now);
  /// Whether a worker may take `id` now: its parent is not in its way, or (an `early` take) is
  /// being loaded. Under mutex_, within one takeBatchLocked.
  bool mayTakeLocked(const TileId& id, bool early, std::chrono::steady_clock::time_point now);
  /// Blocks this worker until `id`'s parent is no longer being loaded: a child taken while its
  /// parent loaded (takeBatchLocked) finishes only after it. False when the pool is stopping.
  bool waitForParentLoad(const TileId& id);
  /// Adds to `wanted` and the queue, coarsest first, the ancestors of `request` that a
  /// dependent codec needs and that are neither wanted, cached nor loading. Under mutex_.
  void queueMissingAncestorsLocked(
      const TileRequest& request,
      std::unordered_map<TileId, std::chrono::steady_clock::time_point, TileIdHash>& wanted,
      std::chrono::steady_clock::time_point now);
  /// Decodes a verified payload into `texels`: a dependent codec's tile against its parent,
  /// pinned in the cache for the decode; when the parent is not cached, against the one the
  /// reader decodes from the nearest cached ancestor down (detail::decodeParent), counted in
  /// parent_fallbacks and the read statistics. The tiles decoded on the way are not cached.
  Result<void> decodeItem(const TileId& id, const TileEntry& entry,
                          std::span<const uint8_t> payload, Image& texels, size_t tile_bytes,
                          CodecScratch& scratch);
  /// Ends a tile's load: the event for the render thread, retries, the in-flight set.
  /// `claimed`: claimLocked was called for this load already (and said it counts).
  void finish(const TileId& id, LoadEvent event, bool failed, bool claimed = false);
  /// Queued tiles at the head of the queue not hinted yet, if the read-ahead window has room;
  /// marks them hinted (size unknown yet). Under mutex_.
  void collectReadAheadLocked(std::vector<TileId>& out);
  /// Looks up `tiles` (in queue order), keeps those that fit the read-ahead window, and tells
  /// the byte source their payload ranges will be read soon.
  void hintReadAhead(std::span<const TileId> tiles);
  /// Forgets a hinted tile (loaded, failed or unwanted). Under mutex_.
  void forgetHintLocked(const TileId& id);
  /// True when an idle worker should add a fresh buffer to the texel pool. Under mutex_.
  bool shouldPrewarm() const;
  /// Records the moment the pool runs out of work (stats_.idle_since). Under mutex_.
  void noteIdleLocked();

  std::shared_ptr<Archive> archive_;
  TileCache& cache_;
  LoaderOptions options_;
  const uint32_t thread_count_;  ///< set before the workers start; they read it unlocked
  const uint32_t helper_count_;  ///< normal-priority helpers (LoaderPriority::kAuto), or 0
  /// Per image: whether its tiles are coded against their parents (ptm). Constant.
  std::vector<bool> dependent_images_;
  bool any_dependent_ = false;  ///< any of dependent_images_; constant
  /// The archive's reads cross a network (ByteSource::linkStats): a second load of a tile
  /// would pay its bytes twice on the link, against the egress budget. Constant.
  bool reads_cost_egress_ = false;
  std::shared_ptr<TexelPool> texel_pool_;
  std::atomic<size_t> last_tile_bytes_{0};  ///< the size of the last tile loaded, for prewarming

  mutable std::mutex mutex_;  // guards every member below
  std::condition_variable work_ready_;
  std::condition_variable idle_;
  // LoaderPriority::kAuto's rescue (docs/runtime.md, "Loader priority").
  std::condition_variable helpers_wake_;  ///< the helpers wait on it, not on work_ready_
  /// The idle workers wait on it during a rescue: woken every frame, a starving thread would
  /// take the lock and, preempted holding it, stall the helpers and the render thread.
  std::condition_variable rescue_over_;
  bool rescuing_ = false;        ///< the helpers load; the idle workers take nothing
  bool helpers_asleep_ = false;  ///< a helper waits for work (setWanted wakes it)
  std::chrono::steady_clock::time_point rescue_began_{};
  std::chrono::steady_clock::time_point check_from_{};    ///< the current window's start
  std::chrono::steady_clock::time_point idle_took_at_{};  ///< an idle worker's last batch
  std::vector<pid_t> idle_tids_;         ///< by worker index, once each has started (else 0)
  std::vector<ThreadTimes> idle_times_;  ///< theirs at the window's start
  /// A tile an idle worker took, with its priority, when and which worker.
  struct Held {
    double priority = 0;
    std::chrono::steady_clock::time_point taken_at;
    uint32_t worker = 0;
  };
  std::unordered_map<TileId, Held, TileIdHash> idle_held_;  ///< until its load finishes
  /// Held tiles a helper loads a second time; the first load to finish delivers and the
  /// later ones, counted in silenced_, are dropped unseen.
  std::unordered_set<TileId, TileIdHash> duplicated_;
  std::unordered_map<TileId, uint32_t, TileIdHash> silenced_;
  std::vector<Pending> queue_;  ///< sorted by priority
  /// Wanted tiles with the moment each became wanted (for the queue-wait estimate).
  std::unordered_map<TileId, std::chrono::steady_clock::time_point, TileIdHash> wanted_;
  std::vector<ActiveRead*> active_reads_;
  LinkEstimator link_;
  std::unordered_set<TileId, TileIdHash> in_flight_;
  /// Batches taken while their first tile's parent was loading, not finished yet.
  uint32_t early_batches_ = 0;
  /// Dependent codecs: the queue's ids, for parentWaitLocked; valid within one take.
  std::unordered_set<TileId, TileIdHash> queued_ids_;
  bool queued_ids_valid_ = false;
  std::unordered_map<TileId, RetryState, TileIdHash> retries_;
  /// Queued tiles whose payloads the byte source was told to fetch ahead, with their payload
  /// bytes; forgotten when the tile finishes or stops being wanted, so a later request hints
  /// it again. Their sum is the read-ahead window's fill.
  std::unordered_map<TileId, uint64_t, TileIdHash> hinted_;
  uint64_t hinted_outstanding_bytes_ = 0;
  std::vector<LoadEvent> events_;
  LoaderStats stats_;
  bool stopping_ = false;
  bool busy_ = false;  ///< queue or in-flight set non-empty at the last noteIdleLocked
  std::vector<std::thread> workers_;
};

}  // namespace tessera::detail
