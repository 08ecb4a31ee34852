#include "loader_pool.h"

#include <pthread.h>
#include <sched.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <limits>

#include <fmt/format.h>

#include <tessera/codec_scratch.h>

#include "codecs/bc1_fast.h"
#include "codecs/bc_layout.h"
#include "reader/parent_chain.h"

namespace tessera::detail {

using Clock = std::chrono::steady_clock;

namespace {

/// Niceness of loader threads (0 is the default, 19 the lowest priority).
constexpr int kLoaderNiceness = 5;

/// LoaderPriority::kAuto: the window over which the helpers judge whether the idle-priority
/// workers starve (waited for a core at least half of it, from /proc's schedstat; where /proc
/// does not say, ready work waited this long while none took any), and the age at which a
/// tile a starving worker holds is loaded again by a helper. One frame at 60 fps.
constexpr std::chrono::milliseconds kStarvedAfter{16};
/// A rescue ends after this, to see whether the idle workers get a core again (the machine
/// may be free by now); if not, the next window starts another.
constexpr std::chrono::milliseconds kRescueProbe{500};

/// Requests of the same level considered for merging with the one a worker takes.
constexpr size_t kMergeCandidates = 32;
/// The same when round trips dominate (LoaderOptions::link_sized_reads): a view's tiles of
/// one level at full HD are about 40-60.
constexpr size_t kLinkMergeCandidates = 128;
/// Bytes a round trip carries (bandwidth x latency) above which a request costs more than a
/// tile's transfer, and batches grow to save requests.
constexpr double kRoundTripMergeBytes = 16 * 1024;

/// Adds a payload, in file order, to `runs`: into the last run when the gap to it is at most
/// `gap_bytes` (one read, gap included), else as a new run. Returns the run's index. The
/// loader's reads and its read-ahead hints merge by this one rule.
size_t addToRuns(std::vector<ByteRange>& runs, uint64_t offset, uint64_t length,
                 uint64_t gap_bytes) {
  if (runs.empty() || offset > runs.back().offset_bytes + runs.back().length_bytes + gap_bytes) {
    runs.push_back({offset, length, nullptr});
  } else {
    ByteRange& run = runs.back();
    run.length_bytes =
        std::max(run.offset_bytes + run.length_bytes, offset + length) - run.offset_bytes;
  }
  return runs.size() - 1;
}

/// The loader's decoded-tile cache as the reader's store of decoded parents, so a process
/// keeps them in one cache: a parent found there is pinned for as long as the handle lives, so
/// eviction cannot recycle its buffer half-way through a decode. The ancestors a fallback
/// decodes are not kept: they would take budget the residency manager never asked for.
class CachedParents final : public ParentStore {
 public:
  explicit CachedParents(TileCache& cache) : cache_(cache) {}
  std::shared_ptr<const Image> find(const TileId& id) override {
    std::shared_ptr<const DecodedTile> tile = cache_.pinIfCached(id);
    if (!tile) return nullptr;
    TileCache* cache = &cache_;
    return std::shared_ptr<const Image>(&tile->texels,
                                        [cache, tile](const Image*) { cache->unpin(tile->id); });
  }
  void offer(const TileId&, const std::shared_ptr<const Image>&) override {}

 private:
  TileCache& cache_;
};

/// Tiles one worker looks up for read-ahead per batch it takes: bounds the time a worker
/// spends on hints before its own read.
constexpr size_t kReadAheadTilesPerCall = 512;

/// Sets the calling thread's scheduling: SCHED_IDLE when `idle`, else niceness `nice`.
/// Lowering one's own priority needs no privilege; a failure leaves the default (and an idle
/// thread that cannot be made idle runs at kLoaderNiceness).
void setThreadPriority(bool idle, int nice) {
  if (idle) {
    sched_param param{};
    if (::pthread_setschedparam(::pthread_self(), SCHED_IDLE, &param) == 0) return;
    nice = kLoaderNiceness;
  }
  if (nice != 0) ::setpriority(PRIO_PROCESS, pid_t(::syscall(SYS_gettid)), nice);
}

/// Thread `tid`'s ThreadTimes from /proc/self/task/TID/schedstat.
ThreadTimes threadTimes(pid_t tid) {
  char path[64];
  std::snprintf(path, sizeof path, "/proc/self/task/%d/schedstat", int(tid));
  FILE* file = std::fopen(path, "re");
  if (!file) return {};
  unsigned long long on_cpu_ns = 0, waited_ns = 0;
  const int fields = std::fscanf(file, "%llu %llu", &on_cpu_ns, &waited_ns);
  std::fclose(file);
  return fields == 2 ? ThreadTimes{int64_t(on_cpu_ns), int64_t(waited_ns)} : ThreadTimes{};
}

/// True when thread `tid` of this process is running or waiting for a core (state R), false
/// when it sleeps (on I/O, a lock, a network read) or /proc does not say.
bool threadRunnable(pid_t tid) {
  char path[64];
  std::snprintf(path, sizeof path, "/proc/self/task/%d/stat", int(tid));
  FILE* file = std::fopen(path, "re");
  if (!file) return false;
  char line[512];
  const bool read = std::fgets(line, sizeof line, file) != nullptr;
  std::fclose(file);
  const char* name_end = read ? std::strrchr(line, ')') : nullptr;
  return name_end && name_end[1] == ' ' && name_end[2] == 'R';
}

/// `error` as the failed load of tile `id`, its message naming the archive and the tile
/// first: a byte source names only its file or URL and the range it read ("http://h/s.tess:
/// bytes=0-99: HTTP 503 Service Unavailable" becomes "http://h/s.tess: tile (0,3,7):
/// bytes=0-99: HTTP 503 Service Unavailable").
LoadEvent failedLoad(const Archive& archive, const TileId& id, const Error& error) {
  const std::string tile = archive.tileName(id);
  std::string message = error.message;
  if (message.find(tile) == std::string::npos) {
    const std::string prefix = archive.name() + ": ";
    if (message.starts_with(prefix)) message.erase(0, prefix.size());
    message = tile + ": " + message;
  }
  LoadEvent event;
  event.id = id;
  event.error = std::move(message);
  event.code = error.code;
  return event;
}

}  // namespace

struct LoaderPool::Batch {
  TileId first;
  bool early = false;  ///< taken while its first tile's parent was loading (takeBatchLocked)
  /// The idle-priority worker that took it (its index), or -1 for a helper or a niceness-5
  /// worker: a starving idle worker's tiles are loaded again by the helpers.
  int32_t idle_worker = -1;
  std::vector<TileId> candidates;
  std::vector<BatchItem> items;
};

LoaderPool::LoaderPool(std::shared_ptr<Archive> archive, TileCache& cache,
                       const LoaderOptions& options)
    : archive_(std::move(archive)),
      cache_(cache),
      options_(options),
      thread_count_(options.threads ? options.threads
                                    : std::max(1u, std::thread::hardware_concurrency())),
      helper_count_(options.priority == LoaderPriority::kAuto
                        ? std::min(thread_count_, std::max(1u, std::thread::hardware_concurrency()))
                        : 0),
      texel_pool_(std::make_shared<TexelPool>(options.recycled_bytes)) {
  for (const ImageInfo& info : archive_->images()) {
    dependent_images_.push_back(codecNeedsParent(info.default_codec) && info.level_count > 1);
    any_dependent_ = any_dependent_ || dependent_images_.back();
  }
  seedLinkEstimate();
  reads_cost_egress_ = archive_->source().linkStats().has_value();
  idle_tids_.assign(thread_count_, 0);
  idle_times_.assign(thread_count_, {});
  for (uint32_t i = 0; i < thread_count_; ++i) workers_.emplace_back([this, i] { run(i); });
  for (uint32_t i = 0; i < helper_count_; ++i) workers_.emplace_back([this, i] { runHelper(i); });
}

void LoaderPool::seedLinkEstimate() {
  // The requests that opened the archive (header, directory ahead) crossed the same link:
  // without them the first frame would know no throughput, and adaptive scheduling would
  // spend a round trip on the coarsest level alone to measure one.
  const std::optional<LinkStats> stats = archive_->source().linkStats();
  if (!stats) return;
  for (const LinkSample& sample : stats->recent) {
    const auto started = sample.finished - std::chrono::duration_cast<Clock::duration>(
                                               std::chrono::duration<double>(sample.seconds));
    link_.readStarted(started);
    link_.readFinished(started, sample.finished, sample.bytes);
  }
}

LoaderPool::~LoaderPool() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
    queue_.clear();
  }
  work_ready_.notify_all();
  helpers_wake_.notify_all();
  rescue_over_.notify_all();
  for (std::thread& worker : workers_) worker.join();
}

void LoaderPool::setWanted(std::span<const TileRequest> requests) {
  const auto now = Clock::now();
  {
    std::lock_guard lock(mutex_);
    decltype(wanted_) wanted;
    wanted.reserve(requests.size() * 2);
    for (const TileRequest& request : requests) {
      auto previous = wanted_.find(request.id);
      wanted.emplace(request.id, previous == wanted_.end() ? now : previous->second);
    }
    for (const Pending& pending : queue_)
      if (!wanted.count(pending.id)) ++stats_.cancelled;
    queue_.clear();
    for (const TileRequest& request : requests) {
      if (in_flight_.count(request.id)) continue;
      if (any_dependent_) queueMissingAncestorsLocked(request, wanted, now);
      queue_.push_back({request.id, request.priority, request.urgency});
    }
    wanted_ = std::move(wanted);
    // Reads in flight whose every tile left: abandoned, so a network read stops using the
    // link (Marvie & Bouatouch, part III). A read with one tile still wanted goes on.
    for (ActiveRead* read : active_reads_)
      if (!read->cancel.load(std::memory_order_relaxed) && !anyWantedLocked(read->tiles)) {
        read->cancel.store(true, std::memory_order_release);
        ++stats_.reads_cancelled;
      }
    for (auto it = hinted_.begin(); it != hinted_.end();) {
      if (wanted_.count(it->first)) {
        ++it;
      } else {
        hinted_outstanding_bytes_ -= it->second;
        it = hinted_.erase(it);
      }
    }
    // Retry state of tiles nobody wants any more is forgotten: a later request starts afresh.
    for (auto it = retries_.begin(); it != retries_.end();)
      it = wanted_.count(it->first) ? std::next(it) : retries_.erase(it);
    stats_.queued = queue_.size();
    noteIdleLocked();
    // Helpers with nothing ready sleep until work comes; they then time the idle workers.
    if (helpers_asleep_ && !queue_.empty()) helpers_wake_.notify_all();
  }
  work_ready_.notify_all();
}

bool LoaderPool::needsParent(const TileId& id) const {
  return id.image < dependent_images_.size() && dependent_images_[id.image] &&
         id.level + 1 < archive_->images()[id.image].level_count;
}

void LoaderPool::queueMissingAncestorsLocked(
    const TileRequest& request, std::unordered_map<TileId, Clock::time_point, TileIdHash>& wanted,
    Clock::time_point now) {
  // A child decodes only against its decoded parent, so a wanted child whose parent nobody
  // asked for (it is resident on the GPU but left the host cache, or the residency manager
  // did not want that level) would wait for ever. Its missing ancestors go first, at its
  // priority; the chain stops at the first one that is wanted, cached or loading.
  TileId missing[32];
  size_t count = 0;
  for (TileId id = request.id; needsParent(id) && count < std::size(missing);) {
    const TileId parent = Archive::parentTile(id);
    if (wanted.count(parent) || in_flight_.count(parent) || cache_.contains(parent)) break;
    missing[count++] = parent;
    id = parent;
  }
  for (size_t i = count; i-- > 0;) {
    auto previous = wanted_.find(missing[i]);
    if (previous == wanted_.end()) ++stats_.parents_queued;
    wanted.emplace(missing[i], previous == wanted_.end() ? now : previous->second);
    queue_.push_back({missing[i], request.priority, request.urgency});
  }
}

LoaderPool::ParentWait LoaderPool::parentWaitLocked(const TileId& id, Clock::time_point now) {
  if (!needsParent(id)) return ParentWait::kNone;
  const TileId parent = Archive::parentTile(id);
  if (in_flight_.count(parent)) return ParentWait::kLoading;
  // The queue's ids, gathered once per take and only when a tile needs them; the set keeps its
  // buckets from one take to the next.
  if (!queued_ids_valid_) {
    queued_ids_.clear();
    for (const Pending& pending : queue_) queued_ids_.insert(pending.id);
    queued_ids_valid_ = true;
  }
  if (!queued_ids_.count(parent)) return ParentWait::kNone;
  // A parent waiting out a backoff does not hold its children: they read it themselves and
  // fail with it, naming both tiles, instead of waiting unseen.
  auto retry = retries_.find(parent);
  return retry == retries_.end() || retry->second.not_before <= now ? ParentWait::kQueued
                                                                    : ParentWait::kNone;
}

bool LoaderPool::mayTakeLocked(const TileId& id, bool early, Clock::time_point now) {
  if (!any_dependent_) return true;
  const ParentWait wait = parentWaitLocked(id, now);
  return wait == ParentWait::kNone || (wait == ParentWait::kLoading && early);
}

bool LoaderPool::waitForParentLoad(const TileId& id) {
  const TileId parent = Archive::parentTile(id);
  std::unique_lock lock(mutex_);
  // finish() wakes every worker when a tile above level 0 (a parent) ends, loaded or not.
  work_ready_.wait(lock, [&] { return stopping_ || !in_flight_.count(parent); });
  return !stopping_;
}

bool LoaderPool::anyWantedLocked(std::span<const TileId> tiles) const {
  return std::any_of(tiles.begin(), tiles.end(),
                     [&](const TileId& id) { return wanted_.count(id) > 0; });
}

void LoaderPool::noteIdleLocked() {
  const bool busy = !queue_.empty() || !in_flight_.empty();
  if (busy_ && !busy) stats_.idle_since = Clock::now();
  busy_ = busy;
}

void LoaderPool::poll(std::vector<LoadEvent>& out) {
  std::lock_guard lock(mutex_);
  for (LoadEvent& event : events_) out.push_back(std::move(event));
  events_.clear();
}

void LoaderPool::inFlight(std::unordered_set<TileId, TileIdHash>& out) const {
  std::lock_guard lock(mutex_);
  out = in_flight_;
}

bool LoaderPool::isRequested(const TileId& id) const {
  std::lock_guard lock(mutex_);
  if (in_flight_.count(id)) return true;
  return std::any_of(queue_.begin(), queue_.end(), [&](const Pending& p) { return p.id == id; });
}

LoaderStats LoaderPool::stats() const {
  std::lock_guard lock(mutex_);
  LoaderStats stats = stats_;
  stats.queued = queue_.size();
  stats.in_flight = in_flight_.size();
  stats.link = link_.estimate();
  return stats;
}

void LoaderPool::waitIdle() {
  std::unique_lock lock(mutex_);
  idle_.wait(lock, [&] {
    if (!in_flight_.empty()) return false;
    // Requests waiting out a retry backoff do not count: they may wait for a long time.
    auto now = Clock::now();
    return std::none_of(queue_.begin(), queue_.end(), [&](const Pending& p) {
      auto it = retries_.find(p.id);
      return it == retries_.end() || it->second.not_before <= now;
    });
  });
}

bool LoaderPool::takeBatchLocked(Batch& batch, Clock::time_point now, bool may_wait) {
  // Dependent codecs: a tile whose parent is loading or queued waits for it, so it decodes
  // against the cached parent instead of reading the parent a second time. When nothing else
  // is ready, a worker takes a tile whose parent is loading (the second pass): it reads the
  // child's payload during the parent's load and decodes it after (waitForParentLoad). Over a
  // network each level then costs one round trip less than a level after the other; a worker
  // that would otherwise sleep only blocks instead, and never on a parent nobody loads, so
  // waits cannot form a cycle (a parent is always a coarser level). At most all workers but
  // one hold such a batch at a time.
  queued_ids_valid_ = false;
  for (const bool early : {false, true}) {
    // One worker always stays free of waits, for the work the next frame may bring.
    if (early && (!may_wait || !any_dependent_ || early_batches_ + 1 >= thread_count_)) break;
    for (size_t i = 0; i < queue_.size(); ++i) {
      auto retry = retries_.find(queue_[i].id);
      if (retry != retries_.end() && retry->second.not_before > now) continue;
      if (!mayTakeLocked(queue_[i].id, early, now)) continue;
      takeLocked(batch, i, early, now);
      return true;
    }
  }
  return false;
}

void LoaderPool::takeLocked(Batch& batch, size_t index, bool early, Clock::time_point now) {
  batch.first = queue_[index].id;
  batch.early = early;
  const uint32_t first_urgency = queue_[index].urgency;
  batch.candidates.clear();
  batch.items.clear();
  if (batch.idle_worker >= 0)
    idle_held_[batch.first] = {queue_[index].priority, now, uint32_t(batch.idle_worker)};
  queue_.erase(queue_.begin() + ptrdiff_t(index));
  in_flight_.insert(batch.first);
  if (early) {
    ++early_batches_;
    ++stats_.children_read_early;
  }
  if (auto it = wanted_.find(batch.first); it != wanted_.end()) link_.queueWait(now - it->second);
  // A fair share of the class's queue at most, so the other workers decode the rest of the
  // screen in parallel instead of waiting for one worker's long batch.
  size_t same_class = 0;
  for (size_t j = index; j < queue_.size(); ++j) same_class += queue_[j].urgency == first_urgency;
  const size_t share = readSizing().whole_class
                           ? std::min(kLinkMergeCandidates, same_class)
                           : std::min(kMergeCandidates, same_class / thread_count_);
  for (size_t j = index; j < queue_.size() && batch.candidates.size() < share; ++j) {
    const TileId& other = queue_[j].id;
    if (other.image != batch.first.image || other.level != batch.first.level ||
        queue_[j].urgency != first_urgency || retries_.count(other))
      continue;
    // An early batch may carry siblings whose parent is loading too; they wait as it does.
    if (mayTakeLocked(other, early, now)) batch.candidates.push_back(other);
  }
  stats_.queued = queue_.size();
}

void LoaderPool::run(uint32_t worker_index) {
  // Loader threads yield the CPU to the render thread (LoaderPriority, docs/runtime.md): with
  // fewer free cores than threads, a frame must not wait for a decode to be preempted.
  const bool idle = options_.priority != LoaderPriority::kNice;
  setThreadPriority(idle, idle ? 0 : kLoaderNiceness);
  CodecScratch scratch;
  Batch batch;
  std::vector<TileId> read_ahead;
  std::unique_lock lock(mutex_);
  idle_tids_[worker_index] = pid_t(::syscall(SYS_gettid));
  for (;;) {
    if (stopping_) return;
    auto now = Clock::now();
    // While the helpers rescue, a starving worker would only hold tiles they must then load
    // again: it waits for the rescue to end.
    if (rescuing_) {
      rescue_over_.wait(lock);
      continue;
    }
    batch.idle_worker = idle ? int32_t(worker_index) : -1;
    if (!takeBatchLocked(batch, now, true)) {
      // Idle: fault in buffers for the next decodes while nothing waits, so the first tiles
      // after a jump skip the page faults and clearing of fresh memory (about 80 us a 256-px
      // RGB tile here). Up to the pool's cap, and only into room the cache budget still has.
      if (shouldPrewarm()) {
        const size_t bytes = last_tile_bytes_.load(std::memory_order_relaxed);
        lock.unlock();
        texel_pool_->give(std::vector<uint8_t>(bytes));
        lock.lock();
        idle_.notify_all();
        continue;
      }
      idle_.notify_all();
      sleepUntilWorkLocked(lock, work_ready_);
      continue;
    }
    idle_took_at_ = now;
    loadTakenBatch(lock, batch, scratch, read_ahead);
  }
}

void LoaderPool::runHelper(uint32_t helper_index) {
  // Normal priority: a helper loads only while the idle-priority workers starve, when other
  // threads keep every core busy, and then takes its fair share of a core like theirs. The
  // first helper watches; the others sleep until it starts a rescue.
  CodecScratch scratch;
  Batch batch;
  std::vector<TileId> read_ahead;
  std::unique_lock lock(mutex_);
  for (;;) {
    if (stopping_) return;
    auto now = Clock::now();
    if (queue_.empty() && in_flight_.empty()) {
      endRescueLocked();
      helpers_asleep_ = true;
      helpers_wake_.wait(lock);
      helpers_asleep_ = false;
      check_from_ = Clock::now();  // the window starts when work comes
      sampleIdleWaitLocked();
      continue;
    }
    if (!rescuing_) {
      if (helper_index != 0) {
        helpers_wake_.wait(lock);
        continue;
      }
      if (now < check_from_ + kStarvedAfter) {
        helpers_wake_.wait_until(lock, check_from_ + kStarvedAfter);
        continue;
      }
      if (!idleWorkersStarvedLocked(now)) continue;
      rescuing_ = true;
      rescue_began_ = now;
      ++stats_.rescues;
      helpers_wake_.notify_all();
    } else if (now > rescue_began_ + kRescueProbe) {
      endRescueLocked();
      continue;
    }
    batch.idle_worker = -1;
    // A starving worker's tiles were the best of the queue when it took them (the view's
    // tiles, after a jump): they go before queued tiles of lower priority, else the view
    // waits for the whole queue, or for the starving worker.
    constexpr double kAny = std::numeric_limits<double>::infinity();
    const double queue_best = queue_.empty() ? kAny : queue_.front().priority;
    if (takeHostageLocked(batch, now, queue_best) || takeBatchLocked(batch, now, false) ||
        takeHostageLocked(batch, now, kAny)) {
      ++stats_.rescued_batches;
      loadTakenBatch(lock, batch, scratch, read_ahead);
      continue;
    }
    // Nothing a helper may take: what is left is in flight (or waits for a backoff, or for
    // its parent); a tile a starving worker holds may be old enough to load again soon.
    auto wake = now + kStarvedAfter / 4;
    helpers_wake_.wait_until(lock, std::min(wake, rescue_began_ + kRescueProbe));
  }
}

void LoaderPool::endRescueLocked() {
  if (!rescuing_) return;
  rescuing_ = false;
  check_from_ = Clock::now();
  sampleIdleWaitLocked();
  rescue_over_.notify_all();  // the idle workers take work again
}

void LoaderPool::sampleIdleWaitLocked() {
  for (size_t i = 0; i < idle_tids_.size(); ++i)
    idle_times_[i] = idle_tids_[i] ? threadTimes(idle_tids_[i]) : ThreadTimes{};
}

bool LoaderPool::idleWorkersStarvedLocked(Clock::time_point now) {
  const int64_t window_ns =
      std::chrono::duration_cast<std::chrono::nanoseconds>(now - check_from_).count();
  // Per worker, the share of the window it starved: for one that wants a core now (runnable),
  // the part it did not get one; for one that sleeps, the waits that ended in the window.
  double starved = 0;
  bool known = window_ns > 0;
  for (size_t i = 0; i < idle_tids_.size() && known; ++i) {
    const ThreadTimes before = idle_times_[i];
    const ThreadTimes after = idle_tids_[i] ? threadTimes(idle_tids_[i]) : ThreadTimes{};
    idle_times_[i] = after;
    known = before.waited_ns >= 0 && after.waited_ns >= before.waited_ns &&
            after.on_cpu_ns >= before.on_cpu_ns;
    if (!known) break;
    const double waited = double(after.waited_ns - before.waited_ns) / double(window_ns);
    const double ran = double(after.on_cpu_ns - before.on_cpu_ns) / double(window_ns);
    starved += threadRunnable(idle_tids_[i]) ? std::max(waited, 1 - ran) : std::min(waited, 1.0);
  }
  check_from_ = now;
  if (known) return starved * 2 >= double(idle_tids_.size());  // half the window, on average
  // Without /proc: ready work waited the whole window and no idle worker took any.
  const Clock::time_point ready_since = readySinceLocked(now);
  return ready_since != Clock::time_point::max() &&
         now - std::max(idle_took_at_, ready_since) >= kStarvedAfter;
}

bool LoaderPool::takeHostageLocked(Batch& batch, Clock::time_point now, double up_to) {
  // The best tile an idle worker took more than kStarvedAfter ago and still holds, not being
  // loaded again already, while that worker waits for a core (a worker waiting on a read is
  // not starving, and its read is not made twice). Over a network the tile is left to its
  // worker: loading it again would read its bytes over the link a second time, which costs
  // egress (the budget counts each tile once) and, on a busy machine, more than the wait.
  if (reads_cost_egress_) return false;
  const TileId* best = nullptr;
  double best_priority = 0;
  std::vector<int8_t> runnable(idle_tids_.size(), -1);
  for (const auto& [id, held] : idle_held_) {
    if (held.taken_at + kStarvedAfter > now || held.priority > up_to || duplicated_.count(id) ||
        !wanted_.count(id))
      continue;
    if (best && held.priority >= best_priority) continue;
    if (any_dependent_ && needsParent(id) && in_flight_.count(Archive::parentTile(id))) continue;
    // A holder that sleeps waits on a read, or on the pool's lock that a starving thread
    // holds: the latter is told by its age.
    int8_t& state = runnable[held.worker];
    if (state < 0) state = threadRunnable(idle_tids_[held.worker]) ? 1 : 0;
    if (state == 0 && held.taken_at + 4 * kStarvedAfter > now) continue;
    best = &id;
    best_priority = held.priority;
  }
  if (!best) return false;
  batch.first = *best;
  batch.early = false;
  batch.candidates.clear();
  batch.items.clear();
  duplicated_.insert(*best);
  ++stats_.tiles_loaded_twice;
  return true;
}

bool LoaderPool::claimLocked(const TileId& id) {
  if (auto it = silenced_.find(id); it != silenced_.end()) {
    if (--it->second == 0) silenced_.erase(it);
    return false;
  }
  if (duplicated_.erase(id)) ++silenced_[id];
  idle_held_.erase(id);
  return true;
}

Clock::time_point LoaderPool::readySinceLocked(Clock::time_point now) const {
  for (const Pending& pending : queue_) {
    auto retry = retries_.find(pending.id);
    if (retry != retries_.end() && retry->second.not_before > now) continue;
    auto wanted = wanted_.find(pending.id);
    return wanted == wanted_.end() ? now : wanted->second;
  }
  return Clock::time_point::max();
}

void LoaderPool::sleepUntilWorkLocked(std::unique_lock<std::mutex>& lock,
                                      std::condition_variable& wake_up) {
  // Until new work, or until the earliest backoff ends.
  auto wake = Clock::time_point::max();
  for (const Pending& pending : queue_) {
    auto it = retries_.find(pending.id);
    if (it != retries_.end()) wake = std::min(wake, it->second.not_before);
  }
  if (wake == Clock::time_point::max())
    wake_up.wait(lock);
  else
    wake_up.wait_until(lock, wake);
}

void LoaderPool::loadTakenBatch(std::unique_lock<std::mutex>& lock, Batch& batch,
                                CodecScratch& scratch, std::vector<TileId>& read_ahead) {
  collectReadAheadLocked(read_ahead);
  lock.unlock();
  // Before this worker's own read: a cold disk then serves the tiles queued behind it
  // while this one reads and decodes, instead of one read at a time per worker.
  hintReadAhead(read_ahead);
  loadBatch(batch, scratch);
  lock.lock();
  if (batch.early) --early_batches_;
}

void LoaderPool::collectReadAheadLocked(std::vector<TileId>& out) {
  out.clear();
  if (options_.read_ahead_bytes == 0 || hinted_outstanding_bytes_ >= options_.read_ahead_bytes)
    return;
  for (size_t i = 0; i < queue_.size() && out.size() < kReadAheadTilesPerCall; ++i)
    if (hinted_.try_emplace(queue_[i].id, 0).second) out.push_back(queue_[i].id);
}

void LoaderPool::forgetHintLocked(const TileId& id) {
  auto it = hinted_.find(id);
  if (it == hinted_.end()) return;
  hinted_outstanding_bytes_ -= it->second;
  hinted_.erase(it);
}

void LoaderPool::hintReadAhead(std::span<const TileId> tiles) {
  if (tiles.empty()) return;
  std::vector<std::pair<TileId, uint64_t>> sized;
  std::vector<ByteRange> ranges;
  std::vector<TileId> not_hinted;
  {
    // The window's room, read once: another worker hinting at the same time may overfill it
    // by one call's worth, which only reads a little further ahead.
    std::unique_lock lock(mutex_);
    uint64_t room =
        options_.read_ahead_bytes - std::min(options_.read_ahead_bytes, hinted_outstanding_bytes_);
    lock.unlock();
    for (const TileId& id : tiles) {
      Result<TileEntry> entry = room ? archive_->tileEntry(id) : Result<TileEntry>(TileEntry{});
      if (!entry || !entry->hasPayload() || room == 0) {
        not_hinted.push_back(id);
        continue;
      }
      ranges.push_back({entry->offset_bytes, entry->length_bytes, nullptr});
      sized.emplace_back(id, entry->length_bytes);
      room -= std::min<uint64_t>(room, entry->length_bytes);
    }
    lock.lock();
    // Tiles that finished or left meanwhile were forgotten already: only those still marked.
    for (const auto& [id, bytes] : sized) {
      auto it = hinted_.find(id);
      if (it == hinted_.end()) continue;
      it->second = bytes;
      hinted_outstanding_bytes_ += bytes;
    }
    for (const TileId& id : not_hinted) forgetHintLocked(id);
  }
  if (ranges.empty()) return;
  // Neighbours in the file merged as the loader's own reads merge them: one hint per run.
  std::sort(ranges.begin(), ranges.end(),
            [](const ByteRange& a, const ByteRange& b) { return a.offset_bytes < b.offset_bytes; });
  std::vector<ByteRange> runs;
  for (const ByteRange& range : ranges)
    addToRuns(runs, range.offset_bytes, range.length_bytes, options_.merge_gap_bytes);
  const uint64_t asked = archive_->source().prefetch(runs);
  std::lock_guard lock(mutex_);
  stats_.hinted_bytes += asked;
}

void LoaderPool::waitPrewarmed() {
  std::unique_lock lock(mutex_);
  idle_.wait(lock, [&] { return stopping_ || !shouldPrewarm(); });
}

bool LoaderPool::shouldPrewarm() const {
  const size_t bytes = last_tile_bytes_.load(std::memory_order_relaxed);
  if (bytes == 0 || stopping_) return false;
  const uint64_t idle = texel_pool_->idleBytes();
  if (idle + bytes > options_.recycled_bytes) return false;
  const CacheStats cache = cache_.stats();
  return cache.bytes + cache.reserved_bytes + idle + bytes <= cache_.budgetBytes();
}

void LoaderPool::finish(const TileId& id, LoadEvent event, bool failed, bool claimed) {
  std::lock_guard lock(mutex_);
  if (!claimed && !claimLocked(id)) return;  // the later of a duplicated tile's two loads
  in_flight_.erase(id);
  forgetHintLocked(id);
  if (failed) {
    ++stats_.failures;
    RetryState& retry = retries_[id];
    ++retry.failures;
    auto backoff = options_.retry_initial * (1u << std::min(retry.failures - 1, 16u));
    retry.not_before =
        Clock::now() + std::min<std::chrono::milliseconds>(backoff, options_.retry_max);
    // Still wanted: back in the queue at its place, to be tried after the backoff.
    if (wanted_.count(id)) queue_.push_back({id, 1e300, UINT32_MAX});
  } else {
    retries_.erase(id);
    // Cancelled in flight, then wanted again before the read gave up: queued again at once
    // (the next frame's setWanted gives it its place).
    if (event.cancelled && wanted_.count(id)) queue_.push_back({id, 1e300, UINT32_MAX});
  }
  noteIdleLocked();
  events_.push_back(std::move(event));
  idle_.notify_all();
  // A finished parent frees the children that waited for it, on any sleeping worker (level 0
  // is nobody's parent).
  if (any_dependent_ && id.level > 0)
    work_ready_.notify_all();
  else if (failed)
    work_ready_.notify_one();
}

Result<void> LoaderPool::decodeItem(const TileId& id, const TileEntry& entry,
                                    std::span<const uint8_t> payload, Image& texels,
                                    size_t tile_bytes, CodecScratch& scratch) {
  const Archive& archive = *archive_;
  if (!codedAgainstParent(archive, id, entry))
    return archive.decodeTileInto(id, entry, payload, texels, &scratch);
  CachedParents cached(cache_);
  if (std::shared_ptr<const Image> parent = cached.find(Archive::parentTile(id)))
    return archive.decodeTileInto(id, entry, payload, texels, *parent, &scratch);
  // The parent left the cache after it loaded (or failed to load): the reader decodes its
  // chain from the nearest cached ancestor down, in the budget, never an unverified or stale
  // parent.
  if (!cache_.reserve(tile_bytes))
    return fail(ErrorCode::kIo, fmt::format("{}: tile cache full of pinned tiles", archive.name()));
  ChainReads reads;
  Result<std::shared_ptr<const Image>> parent = decodeParent(archive, id, cached, &scratch, &reads);
  {
    std::lock_guard lock(mutex_);
    ++stats_.parent_fallbacks;
    stats_.reads += reads.reads;
    stats_.bytes_read += reads.bytes_read;
  }
  Result<void> decoded =
      parent ? archive.decodeTileInto(id, entry, payload, texels, **parent, &scratch)
             : Result<void>(forwardError(parent));
  cache_.unreserve(tile_bytes);
  return decoded;
}

std::vector<LoaderPool::BatchItem> LoaderPool::neighboursInRange(
    std::span<const BatchItem> neighbours, const TileEntry& first, uint64_t gap_bytes,
    uint64_t max_bytes) {
  uint64_t begin = first.offset_bytes;
  uint64_t end = begin + first.length_bytes;
  std::vector<BatchItem> chosen;
  for (const BatchItem& n : neighbours) {
    if (n.entry.offset_bytes < end) continue;
    if (n.entry.offset_bytes - end > gap_bytes) break;
    const uint64_t new_end = n.entry.offset_bytes + n.entry.length_bytes;
    if (new_end - begin > max_bytes) break;
    end = new_end;
    chosen.push_back(n);
  }
  for (auto it = neighbours.rbegin(); it != neighbours.rend(); ++it) {
    const uint64_t n_end = it->entry.offset_bytes + it->entry.length_bytes;
    if (n_end > begin) continue;
    if (begin - n_end > gap_bytes) break;
    if (end - it->entry.offset_bytes > max_bytes) break;
    begin = it->entry.offset_bytes;
    chosen.push_back(*it);
  }
  return chosen;
}

/// A batch's payloads as read: one run per merged read.
struct LoaderPool::BatchReads {
  struct Run {
    ByteRange span;
    std::vector<uint8_t> bytes;
    Result<void> read;  ///< kCancelled: abandoned in flight, or skipped as no longer wanted
  };
  std::vector<Run> runs;
  std::vector<size_t> run_of_item;  ///< per batch item: the run holding its payload (encoded)
  size_t reads = 0;                 ///< read calls made
  uint64_t bytes_read = 0;          ///< bytes they read; abandoned reads count none
};

void LoaderPool::loadBatch(Batch& batch, CodecScratch& scratch) {
  const Archive& archive = *archive_;
  Result<TileEntry> first_entry = archive.tileEntry(batch.first);
  if (!first_entry) {
    finish(batch.first, failedLoad(*archive_, batch.first, first_entry.error()), true);
    return;
  }
  batch.items.push_back({batch.first, *first_entry});
  if (first_entry->hasPayload() && !batch.candidates.empty()) addNeighbours(batch, *first_entry);
  const BatchReads reads = readBatch(batch);
  const size_t tile_bytes = archive.images()[batch.first.image].storedTileBytes();
  last_tile_bytes_.store(tile_bytes, std::memory_order_relaxed);
  for (size_t i = 0; i < batch.items.size(); ++i) {
    const BatchItem& item = batch.items[i];
    Result<std::span<const uint8_t>> payload = payloadOf(item, reads, i);
    if (!payload) {
      // An abandoned read is no failure: its tiles left the wanted set.
      if (payload.error().code == ErrorCode::kCancelled)
        finish(item.id, {item.id, false, true, "", true}, false);
      else
        finish(item.id, failedLoad(archive, item.id, payload.error()), true);
      continue;
    }
    decodeAndDeliver(item, *payload, tile_bytes, scratch);
  }
}

void LoaderPool::addNeighbours(Batch& batch, const TileEntry& first_entry) {
  // Requests of the same level and urgency whose payloads extend the first one's range with
  // gaps under batch_gap_bytes (neighbours on the Hilbert curve usually are).
  std::vector<BatchItem> neighbours;
  for (const TileId& id : batch.candidates) {
    Result<TileEntry> entry = archive_->tileEntry(id);
    if (entry && entry->hasPayload()) neighbours.push_back({id, *entry});
  }
  std::sort(neighbours.begin(), neighbours.end(), [](const auto& a, const auto& b) {
    return a.entry.offset_bytes < b.entry.offset_bytes;
  });
  const std::vector<BatchItem> chosen = neighboursInRange(
      neighbours, first_entry, readSizing().batch_gap_bytes, options_.max_merged_read_bytes);
  // Claim the chosen ones that are still queued (another worker or a new frame may have taken
  // or cancelled them meanwhile).
  const auto now = Clock::now();
  std::lock_guard lock(mutex_);
  for (const auto& item : chosen) {
    auto it = std::find_if(queue_.begin(), queue_.end(),
                           [&](const Pending& p) { return p.id == item.id; });
    if (it == queue_.end()) continue;
    if (batch.idle_worker >= 0)
      idle_held_[item.id] = {it->priority, now, uint32_t(batch.idle_worker)};
    queue_.erase(it);
    in_flight_.insert(item.id);
    if (any_dependent_ && needsParent(item.id) && in_flight_.count(Archive::parentTile(item.id)))
      ++stats_.children_read_early;
    if (auto w = wanted_.find(item.id); w != wanted_.end()) link_.queueWait(now - w->second);
    batch.items.push_back(item);
  }
  stats_.queued = queue_.size();
}

LoaderPool::ReadSizing LoaderPool::readSizing() const {
  ReadSizing sizing{options_.batch_gap_bytes, options_.merge_gap_bytes, false};
  if (!options_.link_sized_reads) return sizing;
  const LinkEstimate link = link_.estimate();
  const double round_trip_bytes = link.bytes_per_s * link.latency_s;
  if (link.reads == 0 || round_trip_bytes < kRoundTripMergeBytes) return sizing;
  // Over a long link a wasted KB costs less than a round trip: a share of one in gap bytes.
  const auto gap = uint64_t(std::min(round_trip_bytes * options_.gap_round_trip_share,
                                     double(options_.max_link_gap_bytes)));
  sizing.batch_gap_bytes = std::max(sizing.batch_gap_bytes, gap);
  sizing.merge_gap_bytes = std::max(sizing.merge_gap_bytes, gap);
  sizing.whole_class = true;
  return sizing;
}

LoaderPool::BatchReads LoaderPool::readBatch(const Batch& batch) {
  // The batch's payloads in file order, each run whose gaps are under merge_gap_bytes in one
  // range. Not ByteSource::readMany: its gap is fixed at 64 KiB, it fails the whole set on one
  // bad read, and the loader must count the reads and bytes it makes.
  std::vector<const BatchItem*> encoded;
  for (const auto& item : batch.items)
    if (item.entry.hasPayload()) encoded.push_back(&item);
  std::sort(encoded.begin(), encoded.end(), [](const BatchItem* a, const BatchItem* b) {
    return a->entry.offset_bytes < b->entry.offset_bytes;
  });
  BatchReads reads;
  std::vector<ByteRange> spans;
  reads.run_of_item.resize(batch.items.size());
  const uint64_t merge_gap = readSizing().merge_gap_bytes;
  for (const BatchItem* item : encoded)
    reads.run_of_item[size_t(item - batch.items.data())] =
        addToRuns(spans, item->entry.offset_bytes, item->entry.length_bytes, merge_gap);
  std::vector<std::vector<TileId>> run_tiles(spans.size());
  for (size_t i = 0; i < batch.items.size(); ++i)
    if (batch.items[i].entry.hasPayload())
      run_tiles[reads.run_of_item[i]].push_back(batch.items[i].id);
  reads.runs.resize(spans.size());
  for (size_t i = 0; i < spans.size(); ++i) reads.runs[i].span = spans[i];
  // Over a network the runs go out together (one multi-range request where the server does
  // them): a round trip per batch, not per run. A local read is short: one run at a time.
  if (spans.size() > 1 && archive_->source().readsRangesTogether()) {
    readRunsTogether(reads, run_tiles);
  } else {
    for (size_t i = 0; i < spans.size(); ++i) readRun(reads, i, std::move(run_tiles[i]));
  }
  if (reads.reads) {
    std::lock_guard lock(mutex_);
    stats_.reads += reads.reads;
    stats_.bytes_read += reads.bytes_read;
  }
  return reads;
}

void LoaderPool::readRun(BatchReads& reads, size_t index, std::vector<TileId> tiles) {
  const Archive& archive = *archive_;
  BatchReads::Run& run = reads.runs[index];
  ActiveRead active;
  active.tiles = std::move(tiles);
  {
    // A run whose tiles all left while the batch's earlier runs were read is not read.
    std::lock_guard lock(mutex_);
    if (!anyWantedLocked(active.tiles)) {
      run.read = fail(ErrorCode::kCancelled, fmt::format("{}: read at offset {} no longer wanted",
                                                         archive.name(), run.span.offset_bytes));
      return;
    }
    active_reads_.push_back(&active);
  }
  run.bytes.resize(run.span.length_bytes);
  const auto started = Clock::now();
  link_.readStarted(started);
  run.read = archive.source().readCancellable(run.span.offset_bytes, run.bytes, active.cancel);
  link_.readFinished(started, Clock::now(), run.read ? run.bytes.size() : 0);
  {
    std::lock_guard lock(mutex_);
    active_reads_.erase(std::find(active_reads_.begin(), active_reads_.end(), &active));
  }
  // An abandoned read counts no bytes (it delivered none); a failed one counts those asked for.
  if (run.read || run.read.error().code != ErrorCode::kCancelled)
    reads.bytes_read += run.bytes.size();
  ++reads.reads;
}

void LoaderPool::readRunsTogether(BatchReads& reads,
                                  const std::vector<std::vector<TileId>>& run_tiles) {
  const Archive& archive = *archive_;
  ActiveRead active;
  for (const std::vector<TileId>& tiles : run_tiles)
    active.tiles.insert(active.tiles.end(), tiles.begin(), tiles.end());
  {
    std::lock_guard lock(mutex_);
    if (!anyWantedLocked(active.tiles)) {
      for (BatchReads::Run& run : reads.runs)
        run.read = fail(ErrorCode::kCancelled, fmt::format("{}: read at offset {} no longer wanted",
                                                           archive.name(), run.span.offset_bytes));
      return;
    }
    active_reads_.push_back(&active);
  }
  std::vector<ByteRange> ranges;
  for (BatchReads::Run& run : reads.runs) {
    run.bytes.resize(run.span.length_bytes);
    ranges.push_back({run.span.offset_bytes, run.span.length_bytes, run.bytes.data()});
  }
  const auto started = Clock::now();
  link_.readStarted(started);
  std::vector<Result<void>> results = archive.source().readEach(ranges, active.cancel);
  uint64_t delivered = 0;
  for (size_t i = 0; i < reads.runs.size(); ++i) {
    BatchReads::Run& run = reads.runs[i];
    run.read = std::move(results[i]);
    if (run.read) delivered += run.bytes.size();
    // As readRun counts: an abandoned range no bytes, a failed one those asked for.
    if (run.read || run.read.error().code != ErrorCode::kCancelled)
      reads.bytes_read += run.bytes.size();
  }
  link_.readFinished(started, Clock::now(), delivered);
  {
    std::lock_guard lock(mutex_);
    active_reads_.erase(std::find(active_reads_.begin(), active_reads_.end(), &active));
  }
  reads.reads += ranges.size();
}

Result<std::span<const uint8_t>> LoaderPool::payloadOf(const BatchItem& item,
                                                       const BatchReads& reads,
                                                       size_t index) const {
  if (!item.entry.hasPayload()) return std::span<const uint8_t>();
  const BatchReads::Run& run = reads.runs[reads.run_of_item[index]];
  if (!run.read) return forwardError(run.read);
  const auto payload = std::span<const uint8_t>(run.bytes).subspan(
      item.entry.offset_bytes - run.span.offset_bytes, item.entry.length_bytes);
  TESSERA_TRY(archive_->verifyPayload(item.id, item.entry, payload));
  return payload;
}

void LoaderPool::decodeAndDeliver(const BatchItem& item, std::span<const uint8_t> payload,
                                  size_t tile_bytes, CodecScratch& scratch) {
  // A child taken while its parent loaded finishes after it (decoding against the cached
  // parent), as every child does: the order does not depend on the worker that took it.
  if (any_dependent_ && needsParent(item.id) && !waitForParentLoad(item.id)) {
    finish(item.id, {item.id, false, true, "", true}, false);
    return;
  }
  if (options_.keep_block_compressed && item.entry.kind == TileKind::kEncoded &&
      (item.entry.codec == Codec::kBc1 || item.entry.codec == Codec::kBc7)) {
    deliverBlocks(item, payload);
    return;
  }
  // The budget counts buffers in flight: no room means try again later, not an error.
  if (!cache_.reserve(tile_bytes)) {
    finish(item.id,
           failedLoad(*archive_, item.id,
                      {ErrorCode::kTooLarge,
                       fmt::format("tile cache full of pinned tiles ({} bytes budget)",
                                   cache_.budgetBytes())}),
           true);
    return;
  }
  const auto started = Clock::now();
  Image texels;
  texels.texels = texel_pool_->take(tile_bytes);
  Result<void> decoded = decodeItem(item.id, item.entry, payload, texels, tile_bytes, scratch);
  const uint64_t decode_ns = uint64_t(
      std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - started).count());
  cache_.unreserve(tile_bytes);
  if (!decoded) {
    texel_pool_->give(std::move(texels.texels));
    finish(item.id, failedLoad(*archive_, item.id, decoded.error()), true);
    return;
  }
  uint64_t transcode_ns = 0;
  StoredBlocks blocks;
  if (options_.transcode_to_bc1) blocks = transcodeToBc1(item, texels, transcode_ns);
  if (blocks.codec != Codec::kRaw) {
    // The texels served only the encoder: recycle them now, the cache keeps the blocks.
    texel_pool_->give(std::move(texels.texels));
    deliver(
        item, decode_ns + transcode_ns,
        [&](bool wanted) {
          if (!wanted) return;
          auto tile = std::make_shared<DecodedTile>();
          tile->id = item.id;
          tile->blocks = std::move(blocks);
          cache_.insert(std::move(tile));
        },
        transcode_ns);
    return;
  }
  deliver(item, decode_ns, [&](bool wanted) {
    if (wanted)
      cache_.insert(texel_pool_->makeTile(item.id, std::move(texels)));
    else
      texel_pool_->give(std::move(texels.texels));
  });
}

StoredBlocks LoaderPool::transcodeToBc1(const BatchItem& item, const Image& texels,
                                        uint64_t& transcode_ns) const {
  // Uniform tiles (no payload) stay one colour, cheaper as texels; alpha would be lost by
  // bc1 (opaque blocks), so tiles with it stay decoded RGBA. Other codecs are left as they
  // are: a lossless archive's user chose exact texels.
  const uint32_t side = archive_->images()[item.id.image].storedTileSidePx();
  if (item.entry.kind != TileKind::kEncoded || item.entry.codec != Codec::kJpeg ||
      texels.sample_type != SampleType::kU8 || (texels.channels != 1 && texels.channels != 3) ||
      texels.width_px != side || texels.height_px != side)
    return {};
  const auto started = Clock::now();
  StoredBlocks blocks;
  blocks.bytes.resize(bcPayloadBytes(Codec::kBc1, side, side));
  if (!encodeBc1Fast(texels.view(), blocks.bytes)) return {};
  blocks.codec = Codec::kBc1;
  blocks.padded_side_px = bcBlocksAlong(side) * kBcBlockSidePx;
  transcode_ns = uint64_t(
      std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - started).count());
  return blocks;
}

void LoaderPool::deliverBlocks(const BatchItem& item, std::span<const uint8_t> payload) {
  const ImageInfo& info = archive_->images()[item.id.image];
  // The size is a bc payload's only structure (docs/codecs.md); the GPU would read past a
  // short one.
  const uint32_t side = info.storedTileSidePx();
  const size_t expected = bcPayloadBytes(item.entry.codec, side, side);
  if (payload.size() != expected) {
    finish(item.id,
           failedLoad(*archive_, item.id,
                      {ErrorCode::kCorrupt,
                       fmt::format("{} payload of {} bytes, expected {} for {} px tiles",
                                   codecName(item.entry.codec), payload.size(), expected,
                                   info.storedTileSidePx())}),
           true);
    return;
  }
  deliver(item, 0, [&](bool wanted) {
    if (!wanted) return;
    auto tile = std::make_shared<DecodedTile>();
    tile->id = item.id;
    tile->blocks.codec = item.entry.codec;
    tile->blocks.padded_side_px = bcBlocksAlong(side) * kBcBlockSidePx;
    tile->blocks.bytes.assign(payload.begin(), payload.end());
    cache_.insert(std::move(tile));
  });
}

void LoaderPool::deliver(const BatchItem& item, uint64_t decode_ns,
                         const std::function<void(bool)>& store,
                         std::optional<uint64_t> transcode_ns) {
  bool claimed = false, wanted = false;
  {
    std::lock_guard lock(mutex_);
    // Of a tile loaded twice (a helper's second load of a starving worker's tile), the first
    // load to finish delivers; the other is dropped unseen.
    claimed = claimLocked(item.id);
    wanted = claimed && wanted_.count(item.id) > 0;
    stats_.decode_ns += decode_ns;
    stats_.transcode_ns += transcode_ns.value_or(0);
    if (wanted) {
      if (transcode_ns) ++stats_.tiles_transcoded;
      ++stats_.tiles_loaded;
      stats_.payload_bytes += item.entry.length_bytes;
    } else if (claimed) {
      ++stats_.stale_dropped;
    }
  }
  // A tile that left every region while it loaded is dropped here (Backes et al., section 6).
  store(wanted);
  if (claimed) finish(item.id, {item.id, wanted, !wanted, ""}, false, true);
}

}  // namespace tessera::detail
