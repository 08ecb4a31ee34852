// The scene streamer end to end on a synthetic scene: the coarsest-level guarantee, reads one
// per planned range on a counting source, the texel budget, and levels refining as the camera
// comes closer.
#include <tessera/scene_stream.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <mutex>
#include <thread>

#include <gtest/gtest.h>

#include <tessera/scene_build.h>

#include "scene/scene_test_support.h"

namespace tessera {
namespace {

using test::CountingSource;
using test::ScratchDir;

std::string buildCity(const ScratchDir& dir, const std::string& spec) {
  return test::buildSyntheticCity(dir, spec);
}

PerspectiveView above(const SceneSummary& summary, double height) {
  return test::cameraAbove(summary, height);
}

struct Opened {
  std::shared_ptr<CountingSource> counter;
  std::shared_ptr<SceneArchive> archive;
};

Opened openCounted(const std::string& path) {
  auto file = openFileSource(path);
  EXPECT_TRUE(file.has_value());
  Opened out;
  out.counter = std::make_shared<CountingSource>(*file);
  auto archive = SceneArchive::open(out.counter);
  EXPECT_TRUE(archive.has_value()) << archive.error().message;
  if (archive.has_value()) out.archive = *archive;
  return out;
}

// Steps frames at one camera until a frame starts no read and picks up nothing.
SceneFrameStats settle(SceneStreamer& streamer, const PerspectiveView& camera) {
  SceneFrameStats stats;
  for (int frame = 0; frame < 200; ++frame) {
    stats = streamer.update(camera);
    if (stats.reads_started == 0 && stats.results_applied == 0 && frame > 0) break;
    streamer.waitForReads();
  }
  return stats;
}

// A network source with given request samples.
class SampledSource final : public ByteSource {
 public:
  explicit SampledSource(std::vector<LinkSample> samples) : samples_(std::move(samples)) {}
  uint64_t sizeBytes() const override { return 0; }
  const std::string& name() const override { return name_; }
  Result<void> read(uint64_t, std::span<uint8_t>) const override { return {}; }
  std::optional<LinkStats> linkStats() const override {
    LinkStats stats;
    stats.recent = samples_;
    return stats;
  }

 private:
  std::vector<LinkSample> samples_;
  std::string name_ = "sampled";
};

TEST(SceneStreamer, MeasuresTheLinkFromItsFirstRequest) {
  const LinkCost fallback{0.0002, 500e6};
  // A local file: no samples, the fallback.
  EXPECT_EQ(measureLinkCost(SampledSource({}), fallback).latency_s, fallback.latency_s);
  // The open's one request (1 MB: 40 ms to the first byte, then 0.4 s) is enough to plan the
  // first frame for a 40 ms link, not for a disk.
  const LinkCost one = measureLinkCost(SampledSource({{{}, 1000000, 0.44, 0.04}}), fallback);
  EXPECT_DOUBLE_EQ(one.latency_s, 0.04);
  EXPECT_NEAR(one.bandwidth_bytes_per_s, 2.5e6, 1);
  // Latency is the median first-byte time; bandwidth all bytes over all transfer time.
  const LinkCost three = measureLinkCost(
      SampledSource({{{}, 100, 0.03, 0.03}, {{}, 1000000, 0.55, 0.05}, {{}, 500000, 0.45, 0.2}}),
      fallback);
  EXPECT_DOUBLE_EQ(three.latency_s, 0.05);
  EXPECT_NEAR(three.bandwidth_bytes_per_s, 1500100 / 0.75, 1);
}

TEST(SceneStreamer, EveryDrawnObjectHasGeometryAndEveryTextureResident) {
  ScratchDir dir;
  Opened scene = openCounted(buildCity(dir, "400:40:7"));
  ASSERT_TRUE(scene.archive);
  auto streamer = SceneStreamer::open(scene.archive);
  ASSERT_TRUE(streamer.has_value()) << streamer.error().message;
  const PerspectiveView camera = above(scene.archive->summary(), 200);
  SceneFrameStats first = (*streamer)->update(camera);
  EXPECT_TRUE((*streamer)->drawableObjects().empty()) << "nothing has arrived on frame one";
  EXPECT_GT(first.waiting_leaves, 0u);
  const SceneFrameStats stats = settle(**streamer, camera);
  EXPECT_EQ(stats.waiting_leaves, 0u);
  EXPECT_GT(stats.visible_objects, 0u);
  EXPECT_EQ((*streamer)->drawableObjects().size(), stats.visible_objects);
  EXPECT_EQ(stats.untextured_objects, 0u);
  for (uint32_t o : (*streamer)->drawableObjects()) {
    const SceneObject* object = (*streamer)->object(o);
    ASSERT_NE(object, nullptr);
    EXPECT_NE((*streamer)->mesh(object->mesh), nullptr) << "object " << o;
    for (uint32_t t : object->textures) {
      if (t == kNoTexture) continue;
      ASSERT_NE((*streamer)->coarsestTile(t), nullptr) << "object " << o << " texture " << t;
      const uint32_t resident = (*streamer)->residentLevel(t);
      EXPECT_LE(resident, (*streamer)->wantedLevel(t)) << "settled: wanted levels are in";
      for (uint32_t level = resident; level + 1 < scene.archive->summary().textures &&
                                      (*streamer)->levelTiles(t, level) != nullptr;
           ++level) {
        EXPECT_FALSE((*streamer)->levelTiles(t, level)->empty());
      }
    }
  }
}

TEST(SceneStreamer, WantedLevelIsTheFinestAnyVisibleObjectNeeds) {
  ScratchDir dir;
  Opened scene = openCounted(buildCity(dir, "400:40:7"));
  ASSERT_TRUE(scene.archive);
  auto streamer = SceneStreamer::open(scene.archive);
  ASSERT_TRUE(streamer.has_value());
  auto textures = scene.archive->textures(0, scene.archive->summary().textures);
  ASSERT_TRUE(textures.has_value());
  // Near (every level matters) and far (leaves take the all-coarsest shortcut).
  for (double height : {15.0, 200.0, 3000.0}) {
    const PerspectiveView camera = above(scene.archive->summary(), height);
    settle(**streamer, camera);
    std::vector<uint32_t> expected(textures->size());
    for (const SceneTexture& t : *textures) expected[t.index] = t.info.level_count - 1;
    for (uint32_t o : (*streamer)->drawableObjects()) {
      const SceneObject* object = (*streamer)->object(o);
      for (uint32_t t : object->textures) {
        if (t == kNoTexture) continue;
        // floor(log2(rho)), rho = max(w, h) * d * pixelAngle / longest side (docs/scenes.md).
        const Box3& b = object->bounds;
        double side = 0, d2 = 0;
        const double eye[3] = {camera.eye_x, camera.eye_y, camera.eye_z};
        for (int a = 0; a < 3; ++a) {
          side = std::max(side, double(b.max[a]) - b.min[a]);
          const double out = std::max({0.0, b.min[a] - eye[a], eye[a] - b.max[a]});
          d2 += out * out;
        }
        const ImageInfo& info = (*textures)[t].info;
        const double rho =
            std::max(info.width_px, info.height_px) * std::sqrt(d2) * pixelAngle(camera) / side;
        const double level =
            std::clamp(std::floor(std::log2(rho)), 0.0, double(info.level_count - 1));
        expected[t] = std::min(expected[t], uint32_t(level));
      }
    }
    for (uint32_t t = 0; t < expected.size(); ++t) {
      EXPECT_EQ((*streamer)->wantedLevel(t), expected[t])
          << "height " << height << " texture " << t;
    }
  }
}

TEST(SceneStreamer, ReadsOncePerPlannedRangeAtEveryGranularity) {
  ScratchDir dir;
  Opened scene = openCounted(buildCity(dir, "600:60:8"));
  ASSERT_TRUE(scene.archive);
  // A slow link makes subtree reads pay; a fast one node and object reads.
  for (const LinkCost link : {LinkCost{0.04, 2.5e6}, LinkCost{0.0, 1e10}}) {
    SceneStreamOptions options;
    options.link = link;
    const uint64_t before_open = scene.counter->reads;
    auto streamer = SceneStreamer::open(scene.archive, options);
    ASSERT_TRUE(streamer.has_value()) << streamer.error().message;
    EXPECT_LE(scene.counter->reads - before_open, 3u) << "node table, texture table, coarse block";
    const uint64_t after_open = scene.counter->reads;
    PerspectiveView camera = above(scene.archive->summary(), 400);
    settle(**streamer, camera);
    camera.eye_y -= 330;  // closer: finer levels by object reads
    settle(**streamer, camera);
    const SceneStreamTotals& totals = (*streamer)->totals();
    EXPECT_GT(totals.reads, 0u);
    EXPECT_EQ(scene.counter->reads - after_open, totals.reads)
        << "one source read per planned read";
    EXPECT_EQ(totals.reads_by_granularity[0] + totals.reads_by_granularity[1] +
                  totals.reads_by_granularity[2],
              totals.reads);
    EXPECT_EQ(totals.read_errors, 0u);
    if (link.latency_s > 0) {
      EXPECT_GT(totals.reads_by_granularity[2], 0u) << "40 ms round trips: subtree reads";
    } else {
      EXPECT_EQ(totals.reads_by_granularity[2], 0u) << "no latency: no byte read for nothing";
      EXPECT_GT(totals.reads_by_granularity[0], 0u) << "refinements read single levels";
    }
  }
}

TEST(SceneStreamer, ReadsALargeSharedNodeAsHeadAndPagesThenOnlyWhatTheViewNeeds) {
  ScratchDir dir;
  Opened scene = openCounted(buildCity(dir, "600:60:8"));
  ASSERT_TRUE(scene.archive);
  auto root = scene.archive->node(0);
  ASSERT_TRUE(root.has_value());
  // Shared meshes and textures live at the root (promotion); on a link where 2 KB cost more
  // than two round trips, its block is too large to read for a corner of the city.
  ASSERT_GT(root->own.length_bytes, 8000u) << "the generator promotes shared items to the root";
  SceneStreamOptions options;
  options.link = LinkCost{1e-6, 1e9};
  auto streamer = SceneStreamer::open(scene.archive, options);
  ASSERT_TRUE(streamer.has_value()) << streamer.error().message;
  scene.counter->largest_read_bytes = 0;
  PerspectiveView camera = above(scene.archive->summary(), 30);
  camera.eye_x = scene.archive->summary().bounds.min[0] + 20;
  const SceneFrameStats stats = settle(**streamer, camera);
  EXPECT_LT(scene.counter->largest_read_bytes, root->own.length_bytes) << "no read of the root";
  EXPECT_GT((*streamer)->totals().reads_by_granularity[0], 0u) << "meshes and levels by object";
  EXPECT_EQ((*streamer)->totals().read_errors, 0u);
  EXPECT_EQ(stats.waiting_leaves, 0u);
  ASSERT_GT(stats.visible_objects, 0u);
  EXPECT_EQ((*streamer)->drawableObjects().size(), stats.visible_objects);
  for (uint32_t o : (*streamer)->drawableObjects()) {
    const SceneObject* object = (*streamer)->object(o);
    EXPECT_NE((*streamer)->mesh(object->mesh), nullptr) << "object " << o;
    for (uint32_t t : object->textures) {
      if (t == kNoTexture) continue;
      EXPECT_LE((*streamer)->residentLevel(t), (*streamer)->wantedLevel(t));
    }
  }
}

// Holds every read back until the test grants it: the order of arrivals is the test's.
class GatedSource final : public ByteSource {
 public:
  explicit GatedSource(std::shared_ptr<ByteSource> inner) : inner_(std::move(inner)) {}
  uint64_t sizeBytes() const override { return inner_->sizeBytes(); }
  const std::string& name() const override { return inner_->name(); }
  Result<void> read(uint64_t offset, std::span<uint8_t> out) const override {
    {
      std::unique_lock lock(mutex_);
      changed_.wait(lock, [&] { return open_ || granted_ > 0; });
      if (!open_) --granted_;
    }
    return inner_->read(offset, out);
  }
  void grant(uint32_t reads) {
    std::lock_guard lock(mutex_);
    granted_ += reads;
    changed_.notify_all();
  }
  void open() {
    std::lock_guard lock(mutex_);
    open_ = true;
    changed_.notify_all();
  }
  void close() {
    std::lock_guard lock(mutex_);
    open_ = false;
  }

 private:
  std::shared_ptr<ByteSource> inner_;
  mutable std::mutex mutex_;  // guards granted_ and open_
  mutable std::condition_variable changed_;
  mutable uint32_t granted_ = 0;
  bool open_ = true;  // while the archive and the streamer open; closed by the test
};

// Closes the gate for a scope and opens it on the way out, so that a failing test never leaves
// workers blocked in a read when the streamer joins them.
class GateClosed {
 public:
  explicit GateClosed(GatedSource& gate) : gate_(gate) { gate_.close(); }
  ~GateClosed() { gate_.open(); }

 private:
  GatedSource& gate_;
};

TEST(SceneStreamer, AtRestAsksForTheViewsPiecesOnceItsNodeReadsHaveLanded) {
  ScratchDir dir;
  const std::string path = buildCity(dir, "600:60:8");
  auto file = openFileSource(path);
  ASSERT_TRUE(file.has_value());
  auto gate = std::make_shared<GatedSource>(*file);
  auto archive = SceneArchive::open(gate);
  ASSERT_TRUE(archive.has_value()) << archive.error().message;
  SceneStreamOptions options;
  options.link = LinkCost{1e-6, 1e9};  // the root is read as head and pages: meshes come later
  options.worker_threads = 1;          // reads run in the order they were queued
  auto streamer = SceneStreamer::open(*archive, options);
  ASSERT_TRUE(streamer.has_value()) << streamer.error().message;
  PerspectiveView camera = above((*archive)->summary(), 120);
  camera.eye_x = (*archive)->summary().bounds.min[0] + 60;
  {
    GateClosed closed(*gate);
    const SceneFrameStats first = (**streamer).update(camera);
    ASSERT_GE(first.reads_started, 3u) << "the root's head and pages, and leaves in 2 reads";
    // Reads land one by one until some visible leaves are in and others wait. At rest, the
    // meshes and levels of the leaves that landed are not asked for meanwhile.
    SceneFrameStats now;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    for (uint32_t granted = 1; granted < first.reads_started; ++granted) {
      gate->grant(1);
      for (uint32_t applied = 0; applied < 1 && std::chrono::steady_clock::now() < deadline;) {
        now = (**streamer).update(camera);
        applied += now.results_applied;
        EXPECT_EQ(now.reads_started, 0u) << "node reads are on their way";
        std::this_thread::yield();
      }
      if (now.visible_objects > 0) break;
    }
    EXPECT_GT(now.visible_objects, 0u) << "some leaves landed, wanting meshes of the root";
    EXPECT_GT(now.waiting_leaves, 0u) << "others are on their way";
  }
  (**streamer).waitForReads();
  const SceneFrameStats after = (**streamer).update(camera);
  EXPECT_GT(after.reads_started, 0u) << "the landed nodes' pieces, all in one wave";
  const SceneFrameStats settled = settle(**streamer, camera);
  EXPECT_EQ(settled.waiting_leaves, 0u);
  EXPECT_EQ((**streamer).drawableObjects().size(), settled.visible_objects);
}

TEST(SceneStreamer, StaysWithinTheTexelBudgetMovingAndStill) {
  ScratchDir dir;
  Opened scene = openCounted(buildCity(dir, "400:40:9"));
  ASSERT_TRUE(scene.archive);
  SceneStreamOptions options;
  options.moving_texel_budget_bytes = 48 << 10;
  options.still_texel_budget_bytes = 160 << 10;
  options.still_after_frames = 3;
  auto streamer = SceneStreamer::open(scene.archive, options);
  ASSERT_TRUE(streamer.has_value());
  PerspectiveView camera = above(scene.archive->summary(), 60);
  uint64_t most_moving = 0, most_still = 0;
  for (int frame = 0; frame < 60; ++frame) {
    if (frame < 30) camera.eye_x += 2;  // moving, then still
    const SceneFrameStats stats = (*streamer)->update(camera);
    // Still from the third unchanged frame (frames 30, 31 and 32 repeat frame 29's camera).
    EXPECT_EQ(stats.moving, frame < 32) << "frame " << frame;
    EXPECT_LE(stats.texel_bytes, stats.texel_budget_bytes) << "frame " << frame;
    EXPECT_EQ(stats.texel_budget_bytes,
              stats.moving ? options.moving_texel_budget_bytes : options.still_texel_budget_bytes);
    (stats.moving ? most_moving : most_still) =
        std::max(stats.moving ? most_moving : most_still, stats.texel_bytes);
    EXPECT_EQ(stats.untextured_objects, 0u);
    (*streamer)->waitForReads();
  }
  EXPECT_GT(most_still, options.moving_texel_budget_bytes) << "still: the larger budget is used";
}

}  // namespace
}  // namespace tessera
