// Adaptive scheduling (Marvie & Bouatouch, part III). The policy on synthetic wanted sets with
// given estimates and an injected clock: coarse levels first, only what fits the time limit
// and the memory budget, the moving/still switch after n seconds, refinement when still. Then
// the streamer over a source whose reads block until the test releases them: a read in flight
// is abandoned when the view jumps away, its tile goes back to unloaded, and update() never
// waits. No sleeps: orderings are forced by the gate.
#include "stream/adaptive.h"

#include <condition_variable>
#include <map>
#include <mutex>
#include <random>
#include <set>
#include <utility>

#include <gtest/gtest.h>

#include <tessera/link.h>

#include "support/synthetic_archive.h"

namespace tessera {
namespace {

using Clock = std::chrono::steady_clock;
using detail::AdaptiveScheduler;
using detail::LinkEstimate;
using detail::TileFacts;

Clock::time_point at(double s) {
  return Clock::time_point{} +
         std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1000 + s));
}

View orthoView(double x, double y, double tpp = 1, uint32_t w = 320, uint32_t h = 240) {
  View view;
  view.ortho = {x, y, tpp, w, h, 0};
  return view;
}

LinkEstimate linkOf(double bytes_per_s, double latency_s) {
  LinkEstimate e;
  e.bytes_per_s = bytes_per_s;
  e.latency_s = latency_s;
  e.reads = 100;
  return e;
}

/// A pyramid of 4 levels as the residency wants it: the coarsest tile (urgency 0), then the
/// view's tiles at levels 2, 1, 0 (4, 16, 64 tiles, urgency 1), then a ring of 36 level-0
/// tiles (urgency 2); every payload 10 kB, every decoded tile 192 KiB.
class AdaptivePolicyTest : public testing::Test {
 protected:
  static constexpr uint32_t kLevels = 4;
  static constexpr uint64_t kTileBytes = 192 * 1024;
  static constexpr uint64_t kPayload = 10'000;

  void SetUp() override {
    double priority = 0;
    wanted_.push_back({{0, 3, 0, 0}, priority++, false, 0});
    for (uint32_t level : {2u, 1u, 0u}) {
      const uint32_t side = 2u << (2 - level);
      for (uint32_t y = 0; y < side; ++y)
        for (uint32_t x = 0; x < side; ++x)
          wanted_.push_back({{0, level, x, y}, priority++, false, 1});
    }
    for (uint32_t i = 0; i < 36; ++i) wanted_.push_back({{0, 0, 100 + i, 0}, priority++, false, 2});
    options_.enabled = true;
    options_.still_after_s = 1;
    options_.moving = {0, 2.0};
    options_.still = {0, 30.0};
  }

  /// Runs the policy over every wanted tile not held; returns the admitted requests.
  std::vector<TileRequest> schedule(AdaptiveScheduler& policy, double t, const LinkEstimate& link,
                                    const View& view = orthoView(0, 0)) {
    std::vector<TileRequest> requests;
    for (const TileRequest& r : wanted_)
      if (!held_.count(key(r.id))) requests.push_back(r);
    report_ = {};
    policy.schedule(
        view, at(t), link, wanted_,
        [&](const TileId& id) {
          TileFacts f;
          f.held = held_.count(key(id)) > 0;
          f.payload_bytes = kPayload;
          f.payload_known = sizes_known_;
          f.parent_ready = not_ready_.count(key(id)) == 0;
          return f;
        },
        requests, report_);
    return requests;
  }

  static std::tuple<uint32_t, uint32_t, uint32_t> key(const TileId& id) {
    return {id.level, id.x, id.y};
  }
  static size_t countAt(const std::vector<TileRequest>& requests, uint32_t level,
                        uint32_t urgency) {
    return size_t(std::count_if(requests.begin(), requests.end(), [&](const TileRequest& r) {
      return r.id.level == level && r.urgency == urgency;
    }));
  }
  AdaptiveScheduler make(uint64_t cache_budget = uint64_t(1) << 30) {
    return AdaptiveScheduler(options_, kLevels, kTileBytes, cache_budget);
  }

  std::vector<TileRequest> wanted_;
  std::set<std::tuple<uint32_t, uint32_t, uint32_t>> held_;
  /// Tiles of a dependent codec (ptm) whose parent is neither in the host cache nor loading.
  std::set<std::tuple<uint32_t, uint32_t, uint32_t>> not_ready_;
  AdaptiveOptions options_;
  FrameReport report_;
  bool sizes_known_ = true;  ///< TileFacts::payload_known of every tile
};

TEST_F(AdaptivePolicyTest, RequestsCoarseLevelsFirstAndOnlyWhatCanArriveInTime) {
  AdaptiveScheduler policy = make();
  // 100 kB/s, 0.1 s latency, 2 s per level: 190 kB can arrive. Level 2 (40 kB) and level 1
  // (160 kB) fit, level 0 (640 kB) does not.
  std::vector<TileRequest> requests = schedule(policy, 0, linkOf(100e3, 0.1));
  EXPECT_TRUE(report_.adaptive);
  EXPECT_FALSE(report_.view_still);
  EXPECT_EQ(report_.requested_level, 1u);
  EXPECT_EQ(report_.budget_bytes, 190'000u);
  EXPECT_EQ(countAt(requests, 3, 0), 1u);
  EXPECT_EQ(countAt(requests, 2, 1), 4u);
  EXPECT_EQ(countAt(requests, 1, 1), 16u);
  EXPECT_EQ(countAt(requests, 0, 1) + countAt(requests, 0, 2), 0u);
  EXPECT_EQ(report_.deferred_tiles, 64u + 36u);
  EXPECT_EQ(report_.requested_bytes, 21 * kPayload);
  // The order is the residency's: priorities ascend.
  for (size_t i = 1; i < requests.size(); ++i)
    EXPECT_LT(requests[i - 1].priority, requests[i].priority);

  // Ten times the rate: level 0 fits (640 kB of 1.9 MB). The ring waits for the view's tiles.
  AdaptiveScheduler faster = make();
  requests = schedule(faster, 0, linkOf(1e6, 0.1));
  EXPECT_EQ(report_.requested_level, 0u);
  EXPECT_EQ(countAt(requests, 0, 1), 64u);
  EXPECT_EQ(countAt(requests, 0, 2), 0u);
  EXPECT_EQ(report_.deferred_tiles, 36u);
}

TEST_F(AdaptivePolicyTest, TheRingFollowsOnceTheViewHasArrivedWhileItsBytesFit) {
  // Every tile the view shows is held: the ring's 36 tiles (360 kB) follow as far as they fit.
  for (const TileRequest& r : wanted_)
    if (r.urgency <= 1) held_.insert(key(r.id));
  AdaptiveScheduler faster = make();
  std::vector<TileRequest> requests = schedule(faster, 0, linkOf(1e6, 0.1));  // 1.9 MB
  EXPECT_EQ(report_.requested_level, 0u);
  EXPECT_EQ(countAt(requests, 0, 2), 36u);
  EXPECT_EQ(report_.deferred_tiles, 0u);
  // At 100 kB/s and 90 ms, 191 kB: 19 ring tiles, the first by priority.
  AdaptiveScheduler slower = make();
  requests = schedule(slower, 0, linkOf(100e3, 0.09));
  EXPECT_EQ(countAt(requests, 0, 2), 19u);
  for (const TileRequest& r : requests) {
    EXPECT_EQ(r.urgency, 2u);
    EXPECT_LT(r.id.x, 119u);
  }
  // One visible tile missing again: the ring waits.
  held_.erase(key(wanted_[30].id));
  AdaptiveScheduler waiting = make();
  requests = schedule(waiting, 0, linkOf(1e6, 0.1));
  EXPECT_EQ(requests.size(), 1u);
  EXPECT_EQ(countAt(requests, 0, 2), 0u);
}

TEST_F(AdaptivePolicyTest, TheCoarsestLevelIsRequestedWhateverTheBudget) {
  AdaptiveScheduler policy = make();
  std::vector<TileRequest> requests = schedule(policy, 0, linkOf(10, 5));  // nothing fits
  EXPECT_EQ(report_.budget_bytes, 0u);
  EXPECT_EQ(report_.requested_level, 3u);
  ASSERT_EQ(requests.size(), 1u);
  EXPECT_EQ(requests[0].id.level, 3u);
}

TEST_F(AdaptivePolicyTest, BeforeTheFirstReadOnlyTheCoarsestLevelIsRequested) {
  AdaptiveScheduler policy = make();
  std::vector<TileRequest> requests = schedule(policy, 0, LinkEstimate{});
  EXPECT_EQ(report_.requested_level, 3u);
  EXPECT_EQ(requests.size(), 1u);
  // With a throughput assumed until then, the levels that fit it.
  options_.assumed_bytes_per_s = 100e3;
  AdaptiveScheduler assuming = make();
  schedule(assuming, 0, LinkEstimate{});
  EXPECT_EQ(report_.requested_level, 1u);  // 200 kB in 2 s: levels 2 and 1
}

TEST_F(AdaptivePolicyTest, TilesHeldOrArrivedCostNoTransferAndLevelsRefineAsTheyArrive) {
  AdaptiveScheduler policy = make();
  // 190 kB a level: level 0's 640 kB does not fit...
  schedule(policy, 0, linkOf(100e3, 0.1));
  EXPECT_EQ(report_.requested_level, 1u);
  // ...until 50 of its 64 tiles are held: 140 kB missing.
  for (uint32_t i = 0; i < 50; ++i) held_.insert({0, i % 8, i / 8});
  std::vector<TileRequest> requests = schedule(policy, 0.1, linkOf(100e3, 0.1));
  EXPECT_EQ(report_.requested_level, 0u);
  EXPECT_EQ(countAt(requests, 0, 1), 14u);
}

TEST_F(AdaptivePolicyTest, MemoryBudgetLimitsTheLevelsAndTheRing) {
  // 20 tiles of memory: the coarsest (1) and level 2 (4) fit, level 1 (16 more) does not.
  options_.moving.memory_bytes = 20 * kTileBytes;
  AdaptiveScheduler policy = make();
  std::vector<TileRequest> requests = schedule(policy, 0, linkOf(1e9, 0));
  EXPECT_EQ(report_.requested_level, 2u);
  EXPECT_EQ(report_.memory_budget_bytes, 20 * kTileBytes);
  EXPECT_LE(report_.memory_bytes, report_.memory_budget_bytes);
  EXPECT_EQ(requests.size(), 5u);
  // 90 tiles: every level of the view (85), and, once the view is held, 5 ring tiles.
  options_.moving.memory_bytes = 90 * kTileBytes;
  for (const TileRequest& r : wanted_)
    if (r.urgency <= 1) held_.insert(key(r.id));
  AdaptiveScheduler roomier = make();
  requests = schedule(roomier, 0, linkOf(1e9, 0));
  EXPECT_EQ(report_.requested_level, 0u);
  EXPECT_EQ(countAt(requests, 0, 2), 5u);
  EXPECT_EQ(report_.memory_bytes, 90 * kTileBytes);
  held_.clear();
  // The cache budget is the ceiling of any memory budget.
  AdaptiveScheduler capped = make(20 * kTileBytes);
  schedule(capped, 0, linkOf(1e9, 0));
  EXPECT_EQ(report_.memory_budget_bytes, 20 * kTileBytes);
  EXPECT_EQ(report_.requested_level, 2u);
}

TEST_F(AdaptivePolicyTest, ADependentTileWaitsForItsParentsRequestOrCountsTheParent) {
  // ptm: a tile decodes only after its parent, and the loader queues a parent nobody asked
  // for. The ring's parents (level 1) are not wanted and not ready: its tiles wait, instead of
  // bringing in parents the memory budget never saw.
  for (const TileRequest& r : wanted_) {
    if (r.urgency <= 1)
      held_.insert(key(r.id));
    else
      not_ready_.insert(key(r.id));
  }
  AdaptiveScheduler policy = make();
  std::vector<TileRequest> requests = schedule(policy, 0, linkOf(1e6, 0.1));  // 1.9 MB
  EXPECT_EQ(countAt(requests, 0, 2), 0u);
  EXPECT_EQ(report_.deferred_tiles, 36u);
  // The parent of the first two ring tiles is wanted ahead of them: they follow it.
  wanted_.insert(wanted_.begin() + 85, TileRequest{{0, 1, 50, 0}, 84.5, false, 2});
  AdaptiveScheduler with_parent = make();
  requests = schedule(with_parent, 0, linkOf(1e6, 0.1));
  EXPECT_EQ(countAt(requests, 1, 2), 1u);
  ASSERT_EQ(countAt(requests, 0, 2), 2u);
  for (const TileRequest& r : requests) {
    if (r.id.level == 0) {
      EXPECT_LT(r.id.x, 102u);
    }
  }

  // The view's level 0 wanted, level 1 held (resident) but not in the host cache: the loader
  // will queue level 1's 16 tiles again, and the memory counts each once.
  held_.clear();
  not_ready_.clear();
  for (const TileRequest& r : wanted_)
    if (r.id.level >= 1 && r.urgency <= 1) held_.insert(key(r.id));
  AdaptiveScheduler ready = make();
  schedule(ready, 0, linkOf(1e9, 0));
  const uint64_t ready_memory = report_.memory_bytes;
  for (const TileRequest& r : wanted_)
    if (r.id.level == 0 && r.urgency == 1) not_ready_.insert(key(r.id));
  AdaptiveScheduler counting = make();
  requests = schedule(counting, 0, linkOf(1e9, 0));
  EXPECT_EQ(countAt(requests, 0, 1), 64u);
  EXPECT_EQ(report_.memory_bytes, ready_memory + 16 * kTileBytes);
}

TEST_F(AdaptivePolicyTest, StillBudgetsApplyAfterTheViewHasNotChangedForNSeconds) {
  AdaptiveScheduler policy = make();
  const LinkEstimate link = linkOf(100e3, 0.1);  // 190 kB in 2 s moving, 2.99 MB in 30 s still
  const View a = orthoView(500, 500), b = orthoView(600, 500);
  schedule(policy, 0, link, a);
  EXPECT_FALSE(report_.view_still);
  EXPECT_EQ(report_.requested_level, 1u);
  schedule(policy, 0.5, link, a);
  EXPECT_FALSE(report_.view_still);
  schedule(policy, 0.999, link, a);
  EXPECT_FALSE(report_.view_still);
  std::vector<TileRequest> requests = schedule(policy, 1.0, link, a);
  EXPECT_TRUE(report_.view_still);
  EXPECT_EQ(report_.budget_bytes, 2'990'000u);
  EXPECT_EQ(report_.requested_level, 0u);  // refinement to the desired level
  EXPECT_EQ(countAt(requests, 0, 1), 64u);
  // The view moves: moving budgets at once, and n seconds more before refining again.
  schedule(policy, 5, link, b);
  EXPECT_FALSE(report_.view_still);
  EXPECT_EQ(report_.requested_level, 1u);
  schedule(policy, 5.9, link, b);
  EXPECT_FALSE(report_.view_still);
  schedule(policy, 6.0, link, b);
  EXPECT_TRUE(report_.view_still);
}

TEST_F(AdaptivePolicyTest, ALevelBeingFetchedIsKeptThroughSmallSwingsOfTheEstimate) {
  AdaptiveScheduler policy = make();
  schedule(policy, 0, linkOf(500e3, 0.1));  // 950 kB: level 0 (640 kB) accepted
  EXPECT_EQ(report_.requested_level, 0u);
  schedule(policy, 0.1, linkOf(300e3, 0.1));  // 570 kB: over budget, under twice of it
  EXPECT_EQ(report_.requested_level, 0u);
  schedule(policy, 0.2, linkOf(100e3, 0.1));  // 190 kB: more than twice over, dropped
  EXPECT_EQ(report_.requested_level, 1u);
  schedule(policy, 0.3, linkOf(300e3, 0.1));  // not fetched now: 570 kB must fit, it does not
  EXPECT_EQ(report_.requested_level, 1u);
}

// --- The streamer over a gated source ---

/// Reads wait at a gate the test opens; a waiting readCancellable returns kCancelled once its
/// flag is set and the test calls `wake` (a bare atomic signals nobody). Counts both.
class GatedSource final : public ByteSource {
 public:
  explicit GatedSource(std::shared_ptr<ByteSource> inner) : inner_(std::move(inner)) {}
  ~GatedSource() override { open(); }
  uint64_t sizeBytes() const override { return inner_->sizeBytes(); }
  const std::string& name() const override { return inner_->name(); }
  Result<void> read(uint64_t offset, std::span<uint8_t> out) const override {
    static const std::atomic<bool> never{false};
    return readCancellable(offset, out, never);
  }
  Result<void> readCancellable(uint64_t offset, std::span<uint8_t> out,
                               const std::atomic<bool>& cancel) const override {
    {
      std::unique_lock lock(mutex_);
      blocked_offsets_.insert(offset);
      changed_.notify_all();
      changed_.wait(lock, [&] { return !closed_ || cancel.load(); });
      blocked_offsets_.erase(blocked_offsets_.find(offset));
      if (closed_) {
        ++cancelled_;
        changed_.notify_all();
        return fail(ErrorCode::kCancelled, "gated read cancelled");
      }
    }
    return inner_->read(offset, out);
  }
  void close() {
    std::lock_guard lock(mutex_);
    closed_ = true;
  }
  void open() {
    std::lock_guard lock(mutex_);
    closed_ = false;
    changed_.notify_all();
  }
  /// Lets waiting readers look at their cancel flags.
  void wake() { changed_.notify_all(); }
  /// Waits until a read is blocked; returns its offset.
  uint64_t waitForBlockedRead() const {
    std::unique_lock lock(mutex_);
    changed_.wait(lock, [&] { return !blocked_offsets_.empty(); });
    return *blocked_offsets_.begin();
  }
  void waitForCancelled(uint64_t n) const {
    std::unique_lock lock(mutex_);
    changed_.wait(lock, [&] { return cancelled_ >= n; });
  }
  uint64_t cancelled() const {
    std::lock_guard lock(mutex_);
    return cancelled_;
  }

 private:
  std::shared_ptr<ByteSource> inner_;
  mutable std::mutex mutex_;
  mutable std::condition_variable changed_;
  bool closed_ = false;
  mutable std::multiset<uint64_t> blocked_offsets_;
  mutable uint64_t cancelled_ = 0;
};

class AdaptiveStreamerTest : public testing::Test {
 protected:
  void SetUp() override {
    test::SyntheticArchiveSpec spec;
    spec.width_px = 2048;
    spec.height_px = 2048;
    const std::vector<uint8_t>& bytes = test::syntheticArchiveBytes(spec);
    ASSERT_FALSE(bytes.empty());
    source_ = std::make_shared<GatedSource>(makeMemorySource(bytes, "mem:adaptive.tess"));
    archive_ = test::openArchiveOrFail(source_);
    ASSERT_TRUE(archive_);
    test::warmDirectory(*archive_);
    options_.loader_threads = 1;
    // No helper threads: under load the default's helpers rescue a starving idle worker and
    // take a second tile to the gate, so "the blocked read" would not be one read.
    options_.loader_priority = LoaderPriority::kNice;
    options_.max_merged_read_bytes = 0;  // one tile per read: the blocked read is one tile
    options_.read_ahead_bytes = 0;
    options_.residency.prefetch = false;
    options_.cache_budget_bytes = size_t(64) << 20;
    options_.adaptive.enabled = true;
    options_.adaptive.clock = [this] { return now_; };
    now_ = at(0);
  }
  void TearDown() override {
    if (source_) source_->open();
    streamer_.reset();
  }
  TileStreamer& start() {
    auto streamer = TileStreamer::create(archive_, options_);
    EXPECT_TRUE(streamer) << streamer.error().message;
    streamer_ = std::move(*streamer);
    return *streamer_;
  }
  FrameReport frame(const View& view) {
    const FrameUpdate& update = streamer_->update(view);
    FrameReport report = update.report;
    ApplyResult result;
    for (const auto& tile : update.uploads) result.accepted.push_back(tile->id);
    streamer_->acknowledge(result);
    return report;
  }
  TileId tileAtOffset(uint64_t offset) const {
    for (const TileId& id : test::allTiles(*archive_)) {
      auto entry = archive_->tileEntry(id);
      if (entry && entry->kind == TileKind::kEncoded && entry->offset_bytes == offset) return id;
    }
    ADD_FAILURE() << "no tile at offset " << offset;
    return {};
  }
  uint32_t coarsest() const { return archive_->images()[0].level_count - 1; }

  std::shared_ptr<GatedSource> source_;
  std::shared_ptr<Archive> archive_;
  StreamerOptions options_;
  std::unique_ptr<TileStreamer> streamer_;
  Clock::time_point now_;
};

TEST_F(AdaptiveStreamerTest, AReadInFlightIsAbandonedWhenTheViewJumpsAwayAndItsTileUnloads) {
  TileStreamer& streamer = start();
  const View a = orthoView(200, 200), b = orthoView(1850, 1850);
  // The coarse levels under both views load first, with the gate open.
  FrameReport settled;
  for (int i = 0; i < 100; ++i) {
    streamer.waitIdleForTesting();
    settled = frame(a);
    if (settled.coverage_desired == 1 && settled.queue_length == 0 && settled.in_flight == 0 &&
        settled.uploads == 0)
      break;
  }
  ASSERT_EQ(settled.coverage_desired, 1);
  ASSERT_EQ(settled.queue_length + settled.in_flight, 0u);
  source_->close();
  frame(b);  // requests b's tiles; the first read blocks at the gate
  const TileId blocked = tileAtOffset(source_->waitForBlockedRead());
  EXPECT_NE(blocked.level, coarsest());
  EXPECT_EQ(streamer.state(blocked), TileState::kRequested);
  // Back to a: nothing of b is wanted there. update() sets the read's flag without waiting.
  const FrameReport back = frame(a);
  EXPECT_GE(back.reads_cancelled_total, 1u);
  source_->wake();
  source_->waitForCancelled(1);
  source_->open();
  streamer.waitIdleForTesting();
  const FrameReport after = frame(a);
  EXPECT_EQ(source_->cancelled(), 1u);
  EXPECT_EQ(after.reads_cancelled_total, 1u);
  EXPECT_EQ(after.load_failures_total, 0u);  // abandoned, not failed: no retry, no error
  EXPECT_EQ(streamer.state(blocked), TileState::kUnloaded);
}

TEST_F(AdaptiveStreamerTest, UpdateNeverWaitsForBlockedReads) {
  TileStreamer& streamer = start();
  source_->close();
  // Every read blocks; a hundred frames over a moving view still return, each reporting the
  // loader's state and the policy's decision.
  FrameReport report;
  for (int i = 0; i < 100; ++i) {
    now_ = at(i / 60.0);
    report = frame(orthoView(300 + 10 * i, 300));
    EXPECT_TRUE(report.adaptive);
    EXPECT_FALSE(report.view_still);
  }
  source_->waitForBlockedRead();
  report = frame(orthoView(300 + 10 * 100, 300));
  EXPECT_EQ(report.tiles_loaded_total, 0u);
  EXPECT_GE(report.in_flight, 1u);
  EXPECT_FALSE(report.fully_covered);
  source_->open();
  streamer.waitIdleForTesting();
}

TEST_F(AdaptiveStreamerTest, RefinesToTheDesiredLevelOnlyOnceTheViewIsStill) {
  // Moving: no time at all for a level (only the coarsest is requested). Still after 1 s:
  // no limit.
  options_.adaptive.moving = {0, 1e-9};
  options_.adaptive.still = {0, 0};
  options_.adaptive.still_after_s = 1;
  TileStreamer& streamer = start();
  const View view = orthoView(1000, 1000);
  FrameReport report;
  for (int i = 0; i < 20; ++i) {
    now_ = at(i * 0.04);  // 0.76 s: still moving mode
    streamer.waitIdleForTesting();
    report = frame(view);
    EXPECT_FALSE(report.view_still);
    EXPECT_EQ(report.requested_level, coarsest());
  }
  EXPECT_LT(report.coverage_desired, 1);
  EXPECT_TRUE(report.fully_covered);  // the coarsest level covers the screen
  for (const TileId& id : test::allTiles(*archive_))
    if (id.level < coarsest()) {
      EXPECT_NE(streamer.state(id), TileState::kResident);
    }
  now_ = at(1.0);
  for (int i = 0; i < 50 && report.coverage_desired < 1; ++i) {
    streamer.waitIdleForTesting();
    report = frame(view);
    EXPECT_TRUE(report.view_still);
  }
  EXPECT_EQ(report.requested_level, report.desired_level);
  EXPECT_EQ(report.coverage_desired, 1);
}

TEST_F(AdaptiveStreamerTest, TheMemoryBudgetBoundsWhatIsRequestedAndLoaded) {
  const uint64_t tile_bytes = archive_->images()[0].storedTileBytes();
  options_.adaptive.moving = {40 * tile_bytes, 0};
  options_.adaptive.still = {40 * tile_bytes, 0};
  options_.loader_threads = 2;
  TileStreamer& streamer = start();
  const View view = orthoView(1000, 1000, 0.5, 640, 480);  // many level-0 tiles
  FrameReport report;
  for (int i = 0; i < 50; ++i) {
    streamer.waitIdleForTesting();
    report = frame(view);
    EXPECT_LE(report.memory_bytes, report.memory_budget_bytes);
    if (report.queue_length == 0 && report.in_flight == 0 && report.uploads == 0) break;
  }
  EXPECT_EQ(report.memory_budget_bytes, 40 * tile_bytes);
  EXPECT_GT(report.requested_level, report.desired_level);  // the view needs more than 40
  EXPECT_LE(streamer.cacheStats().tiles, 40u);
  EXPECT_GT(streamer.cacheStats().tiles, 20u);
  EXPECT_GT(report.deferred_tiles, 0u);
}

// ---- Egress (docs/remote.md, "Egress"): what goes beyond the view over a flight.

TEST_F(AdaptivePolicyTest, TheEgressBudgetBoundsTheRingByTheViewsBytesAndRequests) {
  // The view's 85 tiles (850 kB) are held; the ring's 36 (360 kB) would all fit the link.
  for (const TileRequest& r : wanted_)
    if (r.urgency <= 1) held_.insert(key(r.id));
  const LinkEstimate fast = linkOf(1e6, 0.1);
  auto ringOf = [&](const EgressBudget& egress) {
    options_.egress = egress;
    AdaptiveScheduler policy = make();
    return countAt(schedule(policy, 0, fast), 0, 2);
  };
  EXPECT_EQ(ringOf(EgressBudget::unbounded()), 36u);
  EXPECT_EQ(ringOf(EgressBudget{}), 36u);  // 1.5x: 425 kB and 42 tiles beyond the view
  EXPECT_EQ(ringOf(EgressBudget::metered()), 0u);
  EXPECT_EQ(report_.egress_deferred_tiles, 36u);
  EXPECT_EQ(ringOf({1.25, 0, 0, 0}), 21u);  // 212.5 kB
  EXPECT_EQ(ringOf({0, 1.1, 0, 0}), 8u);    // 8.5 requests
  EXPECT_EQ(ringOf({0, 0, 55'000, 0}), 5u);
  EXPECT_EQ(ringOf({0, 0, 0, 3}), 3u);
  EXPECT_EQ(report_.view_bytes_total, 85 * kPayload);
  EXPECT_EQ(report_.view_tiles_total, 85u);
  EXPECT_EQ(report_.prefetch_tiles_total, 3u);
  EXPECT_EQ(report_.prefetch_bytes_total, 3 * kPayload);
  // Sizes still estimated (directory pages not read): the view's tiles are not counted yet,
  // so nothing goes beyond the view on an estimate.
  sizes_known_ = false;
  EXPECT_EQ(ringOf(EgressBudget{}), 0u);
  EXPECT_EQ(report_.view_bytes_total, 0u);
}

TEST_F(AdaptivePolicyTest, ATileBeyondTheViewIsChargedOnceAndStaysRequestedUntilItArrives) {
  for (const TileRequest& r : wanted_)
    if (r.urgency <= 1) held_.insert(key(r.id));
  options_.egress = {1.25, 0, 0, 0};
  AdaptiveScheduler policy = make();
  const std::vector<TileRequest> first = schedule(policy, 0, linkOf(1e6, 0.1));
  ASSERT_EQ(countAt(first, 0, 2), 21u);
  // Nothing arrived: the next frames request the same 21 and charge nothing more.
  for (double t : {0.1, 0.2}) {
    const std::vector<TileRequest> again = schedule(policy, t, linkOf(1e6, 0.1));
    ASSERT_EQ(again.size(), first.size());
    for (size_t i = 0; i < again.size(); ++i) EXPECT_EQ(again[i].id, first[i].id);
    EXPECT_EQ(report_.prefetch_tiles_total, 21u);
    EXPECT_EQ(report_.view_tiles_total, 85u);
  }
  // They arrive: the budget is spent, no more of the ring follows.
  for (const TileRequest& r : first) held_.insert(key(r.id));
  EXPECT_TRUE(schedule(policy, 0.3, linkOf(1e6, 0.1)).empty());
  EXPECT_EQ(report_.egress_deferred_tiles, 15u);
}

TEST(EgressBudgetTest, ParsesPresetsAndFactorsAndRefusesTheRest) {
  ASSERT_TRUE(parseEgressBudget("default"));
  EXPECT_EQ(parseEgressBudget("default")->byte_factor, 1.5);
  EXPECT_EQ(parseEgressBudget("metered")->byte_factor, 1.0);
  EXPECT_EQ(parseEgressBudget("unbounded")->request_factor, 0.0);
  EXPECT_EQ(parseEgressBudget("2.5")->request_factor, 2.5);
  for (const char* bad : {"", "0.5", "2x", "-1", "nan", "inf", "cheap"}) {
    Result<EgressBudget> budget = parseEgressBudget(bad);
    ASSERT_FALSE(budget) << bad;
    EXPECT_EQ(budget.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(budget.error().message.find("metered"), std::string::npos);
  }
}

/// A flight over a simulated link: the streamer, its residency prefetch and the loader, with
/// the egress budget as the tools set it. The bytes the link carried for tiles stay within
/// the budget's multiple of what the view needed.
class EgressFlightTest : public testing::Test {
 protected:
  /// Flies one still view until loading settles; returns the last frame's report and sets
  /// `link_bytes` to the bytes the simulated link carried after the open.
  FrameReport fly(const EgressBudget& egress, uint64_t& link_bytes) {
    test::SyntheticArchiveSpec spec;
    spec.width_px = 2048;
    spec.height_px = 2048;
    const std::vector<uint8_t>& bytes = test::syntheticArchiveBytes(spec);
    EXPECT_FALSE(bytes.empty());
    auto link =
        makeThrottledSource(makeMemorySource(bytes, "mem:egress.tess"), LinkModel{1e9, 0.0005});
    std::shared_ptr<Archive> archive = test::openArchiveOrFail(link);
    EXPECT_TRUE(archive);
    if (!archive) return {};
    test::warmDirectory(*archive);
    const uint64_t bytes_before = link->totals().bytes;
    StreamerOptions options;
    tuneForRemoteSource(options);
    options.loader_threads = 2;
    options.merge_gap_bytes = 0;  // gap bytes would be charged to neither side
    options.batch_gap_bytes = 0;
    options.cache_budget_bytes = size_t(64) << 20;
    options.adaptive.egress = egress;
    Clock::time_point now = at(0);
    options.adaptive.clock = [&now] { return now; };
    auto streamer = TileStreamer::create(archive, options);
    EXPECT_TRUE(streamer);
    if (!streamer) return {};
    FrameReport report;
    // Still after the first second: the still budgets refine to full detail and let the
    // prefetch follow. Each frame waits for the loads it started, so the flight ends settled.
    for (int frame = 0; frame < 40; ++frame) {
      now = at(0.1 * frame);
      const FrameUpdate& update = (*streamer)->update(orthoView(1024, 1024, 1, 640, 480));
      report = update.report;
      ApplyResult result;
      for (const auto& tile : update.uploads) result.accepted.push_back(tile->id);
      (*streamer)->acknowledge(result);
      (*streamer)->waitIdleForTesting();
    }
    link_bytes = link->totals().bytes - bytes_before;
    return report;
  }
};

TEST_F(EgressFlightTest, TheFlightStaysWithinTheBudgetsMultipleOfTheViewsBytes) {
  uint64_t unbounded_bytes = 0, default_bytes = 0, metered_bytes = 0;
  const FrameReport unbounded = fly(EgressBudget::unbounded(), unbounded_bytes);
  const FrameReport bounded = fly(EgressBudget{}, default_bytes);
  const FrameReport metered = fly(EgressBudget::metered(), metered_bytes);
  ASSERT_GT(bounded.view_bytes_total, 0u);
  EXPECT_EQ(bounded.coverage_desired, 1.0);
  EXPECT_EQ(metered.coverage_desired, 1.0);
  // Without a bound the prefetch takes more than half the view again: the bound binds.
  EXPECT_GT(unbounded.prefetch_bytes_total * 2, unbounded.view_bytes_total);
  EXPECT_LE(bounded.prefetch_bytes_total * 2, bounded.view_bytes_total);
  EXPECT_LE(bounded.prefetch_tiles_total * 2, bounded.view_tiles_total);
  EXPECT_GT(bounded.prefetch_tiles_total, 0u);
  EXPECT_EQ(metered.prefetch_tiles_total, 0u);
  // On the wire (directory pages included, read before the flight): within the multiple.
  EXPECT_LE(double(default_bytes), 1.5 * double(bounded.view_bytes_total));
  EXPECT_LE(metered_bytes, metered.view_bytes_total);
  EXPECT_LT(default_bytes, unbounded_bytes);
}

// ---- Reads sized by the link (StreamerOptions::link_sized_reads; docs/remote.md).

/// Forwards to `inner` and records every read's range.
class RecordingSource final : public ByteSource {
 public:
  explicit RecordingSource(std::shared_ptr<ByteSource> inner) : inner_(std::move(inner)) {}
  uint64_t sizeBytes() const override { return inner_->sizeBytes(); }
  const std::string& name() const override { return inner_->name(); }
  Result<void> read(uint64_t offset, std::span<uint8_t> out) const override {
    record(offset, out.size());
    return inner_->read(offset, out);
  }
  Result<void> readCancellable(uint64_t offset, std::span<uint8_t> out,
                               const std::atomic<bool>& cancel) const override {
    record(offset, out.size());
    return inner_->readCancellable(offset, out, cancel);
  }
  std::vector<std::pair<uint64_t, uint64_t>> takeReads() {
    std::lock_guard lock(mutex_);
    return std::exchange(reads_, {});
  }

 private:
  void record(uint64_t offset, uint64_t length) const {
    std::lock_guard lock(mutex_);
    reads_.emplace_back(offset, length);
  }
  std::shared_ptr<ByteSource> inner_;
  mutable std::mutex mutex_;
  mutable std::vector<std::pair<uint64_t, uint64_t>> reads_;
};

TEST(LinkSizedReadsTest, MergedReadsNeverSpanAWiderGapAndEveryTileGetsItsOwnBytes) {
  test::SyntheticArchiveSpec spec;
  spec.width_px = 2048;
  spec.height_px = 2048;
  const std::vector<uint8_t>& bytes = test::syntheticArchiveBytes(spec);
  ASSERT_FALSE(bytes.empty());
  std::shared_ptr<Archive> reference =
      test::openArchiveOrFail(makeMemorySource(bytes, "mem:reference.tess"));
  ASSERT_TRUE(reference);
  // Payloads in file order, to find the gaps inside a read.
  std::vector<std::pair<uint64_t, uint64_t>> payloads;
  for (const TileId& id : test::allTiles(*reference)) {
    auto entry = reference->tileEntry(id);
    if (entry && entry->hasPayload())
      payloads.emplace_back(entry->offset_bytes, entry->length_bytes);
  }
  std::sort(payloads.begin(), payloads.end());
  std::mt19937 random(34);
  size_t merged_reads = 0;
  for (int trial = 0; trial < 4; ++trial) {
    // 5 ms round trips at 1 Gbit/s, read by 16 threads: the loader measures a round trip
    // carrying well over 16 KiB, so the link sizing takes over (checked below).
    auto recording = std::make_shared<RecordingSource>(
        makeThrottledSource(makeMemorySource(bytes, "mem:link-sized.tess"), LinkModel{1e9, 0.005}));
    std::shared_ptr<Archive> archive = test::openArchiveOrFail(recording);
    ASSERT_TRUE(archive);
    test::warmDirectory(*archive);
    recording->takeReads();
    StreamerOptions options;
    tuneForRemoteSource(options);
    options.adaptive.enabled = false;
    options.merge_gap_bytes = 0;
    options.batch_gap_bytes = 0;
    const uint64_t gap = std::uniform_int_distribution<uint64_t>(0, 40'000)(random);
    options.max_link_gap_bytes = gap;
    auto streamer = TileStreamer::create(archive, options);
    ASSERT_TRUE(streamer);
    size_t checked = 0;
    double round_trip_bytes = 0;
    for (int view = 0; view < 3; ++view) {
      const double x = std::uniform_real_distribution<double>(0, 2048)(random);
      const double y = std::uniform_real_distribution<double>(0, 2048)(random);
      for (int frame = 0; frame < 6; ++frame) {
        const FrameUpdate& update = (*streamer)->update(orthoView(x, y, 1, 640, 480));
        round_trip_bytes = std::max(round_trip_bytes, update.report.link_bytes_per_s *
                                                          update.report.link_latency_ms / 1000);
        ApplyResult result;
        for (const auto& tile : update.uploads) {
          Result<Image> expected = reference->readTile(tile->id);
          ASSERT_TRUE(expected) << expected.error().message;
          EXPECT_EQ(tile->texels.texels, expected->texels) << "trial " << trial;
          result.accepted.push_back(tile->id);
          ++checked;
        }
        (*streamer)->acknowledge(result);
        (*streamer)->waitIdleForTesting();
      }
    }
    EXPECT_GT(checked, 0u);
#if !defined(__SANITIZE_THREAD__) && !defined(__SANITIZE_ADDRESS__)
    // Under a sanitizer the loader measures its own slowdown as a slow link (14 KiB a round
    // trip under TSan, 8.7-15 KiB under ASan with a compiler running beside it): the sizing is
    // checked in Release, the merges' gaps and bytes in all builds.
    EXPECT_GT(round_trip_bytes, 16 * 1024) << "the link sizing never applied";
#endif
    // Inside every read, the bytes between consecutive payloads are at most the gap.
    for (const auto& [offset, length] : recording->takeReads()) {
      uint64_t end = offset;
      size_t carried = 0;
      for (const auto& [p_offset, p_length] : payloads) {
        if (p_offset < offset || p_offset + p_length > offset + length) continue;
        EXPECT_LE(p_offset - end, gap) << "read [" << offset << ", +" << length << ")";
        end = p_offset + p_length;
        ++carried;
      }
      EXPECT_EQ(end, offset + length) << "a read ends on a payload";
      merged_reads += carried > 1;
    }
  }
  EXPECT_GT(merged_reads, 0u) << "the link sizing merged nothing";
}

}  // namespace
}  // namespace tessera
