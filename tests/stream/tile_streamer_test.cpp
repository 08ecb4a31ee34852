// TileStreamer, the per-frame facade: a fixed view reaches full detail, uploads keep their
// budget and go parent before child, the coarsest level stays locked, the cache keeps its
// budget, and a stalled or faulty source never stalls update() or uncovers the screen.
#include <tessera/stream.h>

#include <chrono>
#include <cmath>
#include <set>
#include <thread>
#include <tuple>

#include <gtest/gtest.h>

#include "codecs/bc/bc.h"
#include "codecs/bc1_fast.h"
#include "support/fault_source.h"
#include "support/synthetic_archive.h"

namespace tessera {
namespace {

using test::FaultConfig;
using test::FaultKind;
using test::FaultSource;

using Key = std::tuple<uint32_t, uint32_t, uint32_t>;  // level, x, y
Key keyOf(const TileId& id) {
  return {id.level, id.x, id.y};
}

View orthoView(double centre_x, double centre_y, double tpp = 1, uint32_t w = 320,
               uint32_t h = 240) {
  View view;
  view.ortho = {centre_x, centre_y, tpp, w, h, 0};
  return view;
}

class TileStreamerTest : public testing::TestWithParam<Codec> {
 protected:
  void SetUp() override {
    test::SyntheticArchiveSpec spec;
    spec.codec = codec();
    const std::vector<uint8_t>& bytes = test::syntheticArchiveBytes(spec);
    ASSERT_FALSE(bytes.empty());
    source_ = std::make_shared<FaultSource>(makeMemorySource(bytes, "mem:streamer.tess"));
    archive_ = test::openArchiveOrFail(source_);
    ASSERT_TRUE(archive_);
    test::warmDirectory(*archive_);
    options_.loader_threads = 2;
    options_.cache_budget_bytes = size_t(64) << 20;
    options_.retry_initial = std::chrono::milliseconds(1);
    options_.retry_max = std::chrono::milliseconds(4);
  }

  void TearDown() override {
    if (source_) source_->openGate();
    streamer_.reset();
  }

  virtual Codec codec() const { return GetParam(); }

  TileStreamer& start() {
    auto streamer = TileStreamer::create(archive_, options_);
    EXPECT_TRUE(streamer) << streamer.error().message;
    streamer_ = std::move(*streamer);
    return *streamer_;
  }

  const ImageInfo& info() const { return archive_->images()[0]; }
  uint32_t coarsest() const { return info().level_count - 1; }

  /// One frame as a renderer runs it: update, check the uploads against the budget and the
  /// parent-first rule, upload them all, drop the releases.
  FrameReport frame(const View& view) {
    const FrameUpdate& update = streamer_->update(view);
    const ResidencyOptions& budget = options_.residency;
    EXPECT_LE(update.uploads.size(), budget.upload_budget_tiles);
    for (const auto& tile : update.uploads) {
      const TileId& id = tile->id;
      if (id.level != coarsest()) {
        EXPECT_TRUE(resident_.count({id.level + 1, id.x / 2, id.y / 2}))
            << "tile " << id.level << "," << id.x << "," << id.y << " uploaded before its parent";
      }
      EXPECT_TRUE(resident_.insert(keyOf(id)).second) << "uploaded twice";
    }
    FrameReport report = update.report;
    std::vector<TileId> uploads;
    for (const auto& tile : update.uploads) uploads.push_back(tile->id);
    std::vector<TileId> releases = update.releases;
    ApplyResult result;
    result.accepted = uploads;
    streamer_->acknowledge(result);
    for (const TileId& id : releases) {
      EXPECT_NE(id.level, coarsest()) << "the coarsest level was released";
      resident_.erase(keyOf(id));
    }
    ++frames_;
    return report;
  }

  /// Frames with the loader drained in between until the view is at full detail and nothing
  /// is left to upload, or `max_frames` pass.
  FrameReport settle(const View& view, int max_frames = 100) {
    FrameReport report;
    for (int i = 0; i < max_frames; ++i) {
      streamer_->waitIdleForTesting();
      report = frame(view);
      if (report.coverage_desired == 1 && report.uploads == 0 && report.queue_length == 0 &&
          report.in_flight == 0)
        break;
    }
    return report;
  }

  /// The level-0 tiles an ortho view shows, clipped to the grid.
  std::vector<TileId> visibleTiles(const View& view) const {
    const OrthoView& o = view.ortho;
    double hw = o.viewport_w * o.texels_per_pixel / 2, hh = o.viewport_h * o.texels_per_pixel / 2;
    const double t = info().tile_size_px;
    std::vector<TileId> out;
    for (int64_t y = std::max<int64_t>(0, int64_t((o.centre_y - hh) / t));
         y <= std::min<int64_t>(info().tilesY(0) - 1, int64_t((o.centre_y + hh) / t)); ++y)
      for (int64_t x = std::max<int64_t>(0, int64_t((o.centre_x - hw) / t));
           x <= std::min<int64_t>(info().tilesX(0) - 1, int64_t((o.centre_x + hw) / t)); ++x)
        out.push_back({0, 0, uint32_t(x), uint32_t(y)});
    return out;
  }

  std::shared_ptr<FaultSource> source_;
  std::shared_ptr<Archive> archive_;
  StreamerOptions options_;
  std::unique_ptr<TileStreamer> streamer_;
  std::set<Key> resident_;  ///< what the fake renderer holds
  int frames_ = 0;
};

TEST_P(TileStreamerTest, FixedViewReachesFullDetailWithEveryVisibleTileResident) {
  TileStreamer& streamer = start();
  const View view = orthoView(512, 384);
  FrameReport report = settle(view);
  EXPECT_EQ(report.desired_level, 0u);
  EXPECT_EQ(report.coverage_desired, 1.0);
  EXPECT_TRUE(report.fully_covered);
  EXPECT_EQ(report.finest_full_level, 0u);
  std::vector<TileId> visible = visibleTiles(view);
  EXPECT_EQ(visible.size(), 6u * 4);  // [352, 672] x [264, 504] at 64 px
  for (const TileId& id : visible)
    EXPECT_EQ(streamer.state(id), TileState::kResident) << id.x << "," << id.y;
  EXPECT_EQ(streamer.state({0, coarsest(), 0, 0}), TileState::kLocked);
  EXPECT_GT(report.tiles_loaded_total, 0u);
  EXPECT_EQ(report.load_failures_total, 0u);
  EXPECT_GE(report.bytes_read_total, report.payload_bytes_total);
}

TEST_P(TileStreamerTest, AnUnchangedViewIsNotReplannedButStillGetsItsUploads) {
  start();
  // One frame whose uploads are all declined (offered again later); whether it replanned.
  auto declining = [&](const View& view) {
    const FrameUpdate& update = streamer_->update(view);
    const bool replanned = update.replanned;
    ApplyResult result;
    for (const auto& tile : update.uploads) result.declined.push_back(tile->id);
    streamer_->acknowledge(result);
    return replanned;
  };
  const View view = orthoView(512, 384);
  frame(orthoView(400, 384));
  std::vector<bool> replanned;
  for (int i = 0; i < 6; ++i) {
    streamer_->waitIdleForTesting();
    replanned.push_back(declining(view));
  }
  // The move plans, the first still frame plans once more (no motion now), then the plan holds.
  EXPECT_EQ(replanned, (std::vector<bool>{true, true, false, false, false, false}));
  // The reused plan still hands over what loaded meanwhile, and full detail comes as before.
  const FrameReport report = settle(view);
  EXPECT_EQ(report.coverage_desired, 1.0);
  EXPECT_FALSE(declining(view));
  EXPECT_TRUE(declining(orthoView(513, 384)));
}

TEST_P(TileStreamerTest, ZoomedOutViewIsAtFullDetailOnACoarserLevel) {
  start();
  const View view = orthoView(512, 384, 4);  // 4 texels per pixel: level 2
  FrameReport report = settle(view);
  EXPECT_EQ(report.desired_level, 2u);
  EXPECT_EQ(report.coverage_desired, 1.0);
  EXPECT_EQ(report.finest_full_level, 2u);
  for (const Key& key : resident_) EXPECT_GE(std::get<0>(key), 2u) << "a finer level uploaded";
}

TEST_P(TileStreamerTest, TileStatesFollowTheLoadAndUploadLifeCycle) {
  TileStreamer& streamer = start();
  const TileId top{0, coarsest(), 0, 0};
  const TileId centre{0, 0, 8, 6};
  EXPECT_EQ(streamer.state(centre), TileState::kUnloaded);
  source_->closeGate();
  streamer.update(orthoView(512, 384));
  EXPECT_EQ(streamer.state(centre), TileState::kRequested);
  EXPECT_EQ(streamer.state(top), TileState::kRequested);
  source_->openGate();
  streamer.waitIdleForTesting();
  EXPECT_EQ(streamer.state(centre), TileState::kLoaded);
  EXPECT_EQ(streamer.state(top), TileState::kLoaded);
  const FrameUpdate& update = streamer.update(orthoView(512, 384));
  ASSERT_FALSE(update.uploads.empty());
  EXPECT_EQ(update.uploads.front()->id, top);  // the coarsest goes up first
  std::vector<TileId> uploads;
  for (const auto& tile : update.uploads) uploads.push_back(tile->id);
  EXPECT_EQ(streamer.state(top), TileState::kLoaded);  // handed out, not yet confirmed
  ApplyResult result;
  result.accepted = uploads;
  streamer.acknowledge(result);
  for (const TileId& id : uploads) resident_.insert(keyOf(id));
  EXPECT_EQ(streamer.state(top), TileState::kLocked);
  settle(orthoView(512, 384));
  EXPECT_EQ(streamer.state(centre), TileState::kResident);
}

TEST_P(TileStreamerTest, ADeclinedTileStaysLoadedAndIsOfferedAgain) {
  TileStreamer& streamer = start();
  const View view = orthoView(512, 384);
  streamer.update(view);
  streamer.waitIdleForTesting();
  const FrameUpdate& first = streamer.update(view);
  ASSERT_FALSE(first.uploads.empty());
  const TileId declined = first.uploads.front()->id;
  std::vector<TileId> others;
  for (const auto& tile : first.uploads)
    if (tile->id != declined) others.push_back(tile->id);
  // The renderer had no room for it: not resident, still in the cache.
  ApplyResult result;
  result.declined = {declined};
  result.accepted = others;
  streamer.acknowledge(result);
  EXPECT_EQ(streamer.state(declined), TileState::kLoaded);
  EXPECT_TRUE(streamer.cache().contains(declined));
  const FrameUpdate& second = streamer.update(view);
  EXPECT_TRUE(std::any_of(second.uploads.begin(), second.uploads.end(), [&](const auto& tile) {
    return tile->id == declined;
  })) << "a declined tile is offered again";
}

TEST_P(TileStreamerTest, ATileTheRendererDropsIsOfferedAgainFromTheCache) {
  TileStreamer& streamer = start();
  const View view = orthoView(512, 384);
  settle(view);
  const TileId centre{0, 0, 8, 6};
  ASSERT_EQ(streamer.state(centre), TileState::kResident);
  // The renderer gave it up on its own (a clipmap slot taken, say): no longer resident, still
  // in the cache, and handed over again without a new read.
  const uint64_t reads = streamer.update(view).report.reads_total;
  ApplyResult result;
  result.dropped = {centre};
  streamer.acknowledge(result);
  EXPECT_EQ(streamer.state(centre), TileState::kLoaded);
  const FrameUpdate& again = streamer.update(view);
  EXPECT_TRUE(std::any_of(again.uploads.begin(), again.uploads.end(), [&](const auto& tile) {
    return tile->id == centre;
  })) << "a dropped tile that is still wanted is offered again";
  EXPECT_EQ(again.report.reads_total, reads);
}

TEST_P(TileStreamerTest, UploadsKeepTheTileBudgetAndGoParentBeforeChild) {
  options_.residency.upload_budget_tiles = 5;
  start();
  // The renderer-side checks live in frame(): budget, parent resident first, no duplicates.
  FrameReport report = settle(orthoView(512, 384));
  EXPECT_EQ(report.coverage_desired, 1.0);
  EXPECT_GT(frames_, 5) << "a budget of 5 tiles a frame should spread the uploads";
  // And while panning, with releases in between.
  for (int i = 0; i < 30; ++i) {
    streamer_->waitIdleForTesting();
    frame(orthoView(300 + 15 * i, 300 + 5 * i));
  }
}

TEST_P(TileStreamerTest, UploadsKeepTheByteBudget) {
  const uint64_t tile_bytes = info().storedTileBytes();
  options_.residency.upload_budget_tiles = 1000;
  options_.residency.upload_budget_bytes = tile_bytes * 5 / 2;  // two and a half tiles
  options_.residency.adaptive_upload.enabled = false;           // fixed
  TileStreamer& streamer = start();
  for (int i = 0; i < 20; ++i) {
    streamer.waitIdleForTesting();
    const FrameUpdate& update = streamer.update(orthoView(512, 384));
    if (update.uploads.size() > 1) {
      EXPECT_LE(update.report.upload_bytes, options_.residency.upload_budget_bytes)
          << update.uploads.size() << " tiles in frame " << i;
    }
    ApplyResult result;
    for (const auto& tile : update.uploads) result.accepted.push_back(tile->id);
    streamer.acknowledge(result);
  }
}

TEST_P(TileStreamerTest, TheAdaptiveBudgetFollowsTheRenderersMeasuredUploadTime) {
  const uint64_t tile_bytes = info().storedTileBytes();
  options_.residency.upload_budget_tiles = 1000;
  AdaptiveUploadOptions& adaptive = options_.residency.adaptive_upload;
  adaptive.frame_ms = 10;
  adaptive.upload_share = 0.5;  // 5 ms a frame
  adaptive.min_bytes = 1;
  adaptive.max_bytes = tile_bytes * 1000;
  adaptive.smoothing = 1;  // each frame's measurement is the estimate
  TileStreamer& streamer = start();
  // The renderer says each tile took 2.5 ms: two tiles fit in 5 ms.
  bool measured = false, limited = false;
  for (int i = 0; i < 20; ++i) {
    streamer.waitIdleForTesting();
    const FrameUpdate& update = streamer.update(orthoView(512, 384));
    if (measured && !update.uploads.empty()) {
      EXPECT_EQ(update.report.upload_budget_bytes, 2 * tile_bytes) << "frame " << i;
      EXPECT_LE(update.uploads.size(), 2u) << "frame " << i;
      limited = true;
    }
    ApplyResult result;
    for (const auto& tile : update.uploads) result.accepted.push_back(tile->id);
    result.upload_ms = 2.5 * double(update.uploads.size());
    streamer.acknowledge(result);
    measured = measured || !update.uploads.empty();
  }
  EXPECT_TRUE(limited);
}

TEST_P(TileStreamerTest, UpdateDoesNotBlockWhileEveryLoaderIsStuckInARead) {
  TileStreamer& streamer = start();
  const View view = orthoView(512, 384);
  source_->closeGate();
  frame(view);
  // Every tile of a dependent codec (ptm) waits for the coarsest one: one loader reads it and
  // the others wait for work, not for the source.
  const uint32_t readers = codecNeedsParent(codec()) ? 1 : options_.loader_threads;
  ASSERT_TRUE(source_->waitUntilBlocked(readers)) << "the loaders never reached the source";
  // The loader threads sit inside read(): update() on this thread must still come back.
  for (int i = 0; i < 3; ++i) {
    FrameReport report = frame(view);
    EXPECT_FALSE(report.fully_covered);
    EXPECT_EQ(report.uploads, 0u);
    EXPECT_GT(report.queue_length, 0u);
    EXPECT_GT(report.in_flight, 0u);
  }
  EXPECT_EQ(streamer.state({0, coarsest(), 0, 0}), TileState::kRequested);
  source_->openGate();
  FrameReport report = settle(view);
  EXPECT_EQ(report.coverage_desired, 1.0);
  EXPECT_TRUE(report.fully_covered);
}

TEST_P(TileStreamerTest, CacheStaysWithinItsBudgetWhilePanning) {
  const size_t per_tile = info().storedTileBytes() + sizeof(DecodedTile);
  options_.cache_budget_bytes = 120 * per_tile;
  TileStreamer& streamer = start();
  settle(orthoView(180, 180));
  for (int i = 0; i < 60; ++i) {
    streamer.waitIdleForTesting();
    FrameReport report = frame(orthoView(180 + 11 * i, 180 + 7 * i));
    EXPECT_TRUE(report.fully_covered) << "frame " << i;
  }
  CacheStats stats = streamer.cacheStats();
  EXPECT_LE(stats.peak_bytes, options_.cache_budget_bytes);
  EXPECT_LE(stats.bytes + stats.reserved_bytes, options_.cache_budget_bytes);
  EXPECT_GT(stats.evictions, 0u) << "the pan should put the cache under pressure";
  EXPECT_EQ(streamer.state({0, coarsest(), 0, 0}), TileState::kLocked);
  FrameReport report = settle(orthoView(180 + 11 * 59, 180 + 7 * 59));
  EXPECT_EQ(report.coverage_desired, 1.0);
}

TEST_P(TileStreamerTest, ReachesFullDetailWithABudgetBelowTheWantedSet) {
  // 100 tiles: above the 64 tiles create() demands, below the ~150 tiles the clip regions of a
  // 320x240 view want at 64 px. The view must still reach full detail: the visible tiles and
  // their ancestors matter more than the rest of the clip region.
  const size_t per_tile = info().storedTileBytes() + sizeof(DecodedTile);
  for (bool viewer_shift : {true, false}) {
    SCOPED_TRACE(viewer_shift ? "viewer-shift" : "lru");
    options_.cache_budget_bytes = 100 * per_tile;
    options_.viewer_shift_eviction = viewer_shift;
    resident_.clear();
    TileStreamer& streamer = start();
    for (View view : {orthoView(600, 400), orthoView(200, 400), orthoView(900, 400),
                      orthoView(600, 400, 4), orthoView(100, 700, 8), orthoView(950, 100)}) {
      double x = view.ortho.centre_x;
      FrameReport report = settle(view);
      EXPECT_EQ(report.coverage_desired, 1.0) << "at x " << x;
      EXPECT_TRUE(report.fully_covered);
    }
    EXPECT_LE(streamer.cacheStats().peak_bytes, options_.cache_budget_bytes);
    streamer_.reset();
  }
}

TEST_P(TileStreamerTest, FaultsKeepTheScreenCoveredAndLoadingRecoversWhenTheyStop) {
  TileStreamer& streamer = start();
  ASSERT_EQ(settle(orthoView(200, 200)).coverage_desired, 1.0);
  source_->setFaults({FaultKind::kFlipBytes, 1, 0, 256});
  const View far = orthoView(850, 600);
  FrameReport report;
  for (int i = 0; i < 10; ++i) {
    streamer.waitIdleForTesting();
    report = frame(far);
    EXPECT_TRUE(report.fully_covered) << "frame " << i;
  }
  EXPECT_LT(report.coverage_desired, 1.0);
  EXPECT_GT(report.load_failures_total, 0u);
  source_->stopFaulting();
  auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (report.coverage_desired < 1 && std::chrono::steady_clock::now() < deadline) {
    streamer.waitIdleForTesting();
    report = frame(far);
    std::this_thread::yield();
  }
  EXPECT_EQ(report.coverage_desired, 1.0);
  for (const TileId& id : visibleTiles(far)) EXPECT_EQ(streamer.state(id), TileState::kResident);
}

TEST_P(TileStreamerTest, CreateRefusesABudgetBelowSixtyFourTiles) {
  options_.cache_budget_bytes = 1000;
  auto streamer = TileStreamer::create(archive_, options_);
  ASSERT_FALSE(streamer);
  EXPECT_EQ(streamer.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(streamer.error().message.find("streamer.tess"), std::string::npos);
  EXPECT_FALSE(TileStreamer::create(nullptr, StreamerOptions{}));
}

INSTANTIATE_TEST_SUITE_P(Codecs, TileStreamerTest,
                         testing::Values(Codec::kZstd, Codec::kJpeg, Codec::kPtm),
                         [](const testing::TestParamInfo<Codec>& param_info) {
                           return std::string(codecName(param_info.param));
                         });

/// A small archive (300 x 220, 64-px tiles with a 1-px border: 66 px, padded to 68) of the
/// codec under test: bc encoders are slow, and the padding only shows off a multiple of 4.
class BlockStreamerTest : public TileStreamerTest {
 protected:
  void SetUp() override {
    test::SyntheticArchiveSpec spec;
    spec.width_px = 300;
    spec.height_px = 220;
    spec.border_px = 1;
    spec.codec = codec();
    const std::vector<uint8_t>& bytes = test::syntheticArchiveBytes(spec);
    ASSERT_FALSE(bytes.empty());
    source_ = std::make_shared<FaultSource>(makeMemorySource(bytes, "mem:blocks.tess"));
    archive_ = test::openArchiveOrFail(source_);
    ASSERT_TRUE(archive_);
    options_.loader_threads = 2;
  }
};

// With keep_block_compressed, a bc tile with a payload is handed over as its stored blocks
// (byte for byte the payload, no texels); a uniform tile, which has no payload, and a tile of
// any other codec still arrive decoded.
TEST_P(BlockStreamerTest, KeepBlockCompressedHandsBcPayloadsOverAsStored) {
  options_.keep_block_compressed = true;
  TileStreamer& streamer = start();
  const View view = orthoView(300, 200, 1.5, 160, 120);
  const bool bc = codec() == Codec::kBc1 || codec() == Codec::kBc7;
  const uint32_t padded = (info().storedTileSidePx() + 3) / 4 * 4;
  size_t kept = 0, decoded = 0;
  for (int i = 0; i < 100; ++i) {
    streamer.waitIdleForTesting();
    const FrameUpdate& update = streamer.update(view);
    ApplyResult result;
    for (const auto& tile : update.uploads) {
      result.accepted.push_back(tile->id);
      auto entry = archive_->tileEntry(tile->id);
      ASSERT_TRUE(entry) << entry.error().message;
      if (!tile->keptAsBlocks()) {
        ++decoded;
        EXPECT_FALSE(bc && entry->kind == TileKind::kEncoded) << "a bc payload was decoded";
        EXPECT_EQ(tile->texels.texels.size(), info().storedTileBytes());
        continue;
      }
      ++kept;
      EXPECT_TRUE(bc);
      EXPECT_EQ(tile->blocks.codec, codec());
      EXPECT_EQ(tile->blocks.padded_side_px, padded);
      EXPECT_TRUE(tile->texels.texels.empty());
      auto payload = archive_->readPayload(tile->id, *entry);
      ASSERT_TRUE(payload) << payload.error().message;
      EXPECT_EQ(tile->blocks.bytes, *payload);
      EXPECT_EQ(tile->uploadBytes().size(), payload->size());
    }
    const FrameReport report = update.report;
    streamer.acknowledge(result);
    if (report.coverage_desired == 1 && report.uploads == 0 && report.queue_length == 0 &&
        report.in_flight == 0)
      break;
  }
  EXPECT_GT(kept + decoded, 0u);
  EXPECT_EQ(kept > 0, bc);
}

/// PSNR over R, G and B of a decoded bc1 tile (RGBA, padded side) against the JPEG decode
/// of the same tile (grey spread, or RGB), over the stored tile only.
double bc1Psnr(const Image& rgba, const Image& jpeg) {
  double squared = 0;
  for (uint32_t y = 0; y < jpeg.height_px; ++y)
    for (uint32_t x = 0; x < jpeg.width_px; ++x)
      for (uint32_t c = 0; c < 3; ++c) {
        const double want = jpeg.row(y)[x * jpeg.channels + std::min(c, jpeg.channels - 1)];
        const double got = rgba.row(y)[x * 4 + c];
        squared += (want - got) * (want - got);
      }
  const double mse = squared / (double(jpeg.width_px) * jpeg.height_px * 3);
  return mse == 0 ? 99.0 : 10 * std::log10(255.0 * 255.0 / mse);
}

// With transcode_to_bc1, a JPEG tile with a payload is decoded and handed over as bc1 blocks
// in the stored layout: the fast encoder's blocks for the JPEG decode, within its error of it,
// at an eighth of RGBA's upload bytes; uniform tiles and other codecs
// arrive decoded, and the report counts the transcoded tiles and their time.
TEST_P(BlockStreamerTest, TranscodeToBc1HandsJpegTilesOverAsBc1Blocks) {
  options_.transcode_to_bc1 = true;
  TileStreamer& streamer = start();
  const View view = orthoView(300, 200, 1.5, 160, 120);
  const bool jpeg = codec() == Codec::kJpeg;
  const uint32_t side = info().storedTileSidePx();
  const uint32_t padded = (side + 3) / 4 * 4;
  size_t kept = 0, decoded = 0;
  FrameReport last;
  for (int i = 0; i < 100; ++i) {
    streamer.waitIdleForTesting();
    const FrameUpdate& update = streamer.update(view);
    ApplyResult result;
    for (const auto& tile : update.uploads) {
      result.accepted.push_back(tile->id);
      auto entry = archive_->tileEntry(tile->id);
      ASSERT_TRUE(entry) << entry.error().message;
      if (!tile->keptAsBlocks()) {
        ++decoded;
        EXPECT_FALSE(jpeg && entry->kind == TileKind::kEncoded) << "a JPEG tile was not transcoded";
        continue;
      }
      ++kept;
      ASSERT_TRUE(jpeg);
      EXPECT_EQ(tile->blocks.codec, Codec::kBc1);
      EXPECT_EQ(tile->blocks.padded_side_px, padded);
      EXPECT_TRUE(tile->texels.texels.empty());
      EXPECT_EQ(tile->uploadBytes().size(), size_t(padded) * padded * 4 / 8);
      auto reference = archive_->readTile(tile->id);
      ASSERT_TRUE(reference) << reference.error().message;
      ASSERT_EQ(reference->width_px, side);
      // Byte for byte the fast encoder's output for the JPEG decode, so the error is its
      // error; the floor checks that error on this archive's busy synthetic picture.
      std::vector<uint8_t> expected(tile->blocks.bytes.size());
      ASSERT_TRUE(detail::encodeBc1Fast(reference->view(), expected));
      EXPECT_EQ(tile->blocks.bytes, expected);
      Image rgba(padded, padded, 4);
      ASSERT_TRUE(detail::decodeBc1(tile->blocks.bytes, rgba, nullptr, nullptr));
      // 32.7 dB at worst here.
      EXPECT_GT(bc1Psnr(rgba, *reference), 30.0) << "tile " << tile->id.x << "," << tile->id.y;
    }
    last = update.report;
    streamer.acknowledge(result);
    if (last.coverage_desired == 1 && last.uploads == 0 && last.queue_length == 0 &&
        last.in_flight == 0)
      break;
  }
  EXPECT_GT(kept + decoded, 0u);
  EXPECT_EQ(kept > 0, jpeg);
  EXPECT_EQ(last.tiles_transcoded_total > 0, jpeg);
  EXPECT_GE(last.tiles_transcoded_total, kept);
  EXPECT_LE(last.transcode_ms_total, last.decode_ms_total);
  EXPECT_EQ(last.transcode_ms_total > 0, jpeg);
}

// Tiles with alpha keep it: with transcode_to_bc1 a JPEG archive with an alpha plane (grey +
// alpha and RGBA) still hands its tiles over decoded, as bc1's opaque blocks would lose it.
TEST(TranscodeToBc1, LeavesJpegTilesWithAlphaDecoded) {
  for (uint32_t channels : {2u, 4u}) {
    SCOPED_TRACE(channels);
    test::SyntheticArchiveSpec spec;
    spec.width_px = 300;
    spec.height_px = 220;
    spec.channels = channels;
    spec.codec = Codec::kJpeg;
    std::shared_ptr<Archive> archive = test::openArchiveOrFail(
        makeMemorySource(test::syntheticArchiveBytes(spec), "mem:alpha.tess"));
    ASSERT_TRUE(archive);
    StreamerOptions options;
    options.loader_threads = 2;
    options.transcode_to_bc1 = true;
    auto streamer = TileStreamer::create(archive, options);
    ASSERT_TRUE(streamer) << streamer.error().message;
    const View view = orthoView(150, 110, 1.5, 160, 120);
    size_t delivered = 0;
    FrameReport last;
    for (int i = 0; i < 100; ++i) {
      (*streamer)->waitIdleForTesting();
      const FrameUpdate& update = (*streamer)->update(view);
      ApplyResult result;
      for (const auto& tile : update.uploads) {
        result.accepted.push_back(tile->id);
        ++delivered;
        EXPECT_FALSE(tile->keptAsBlocks());
        EXPECT_EQ(tile->texels.texels.size(), archive->images()[0].storedTileBytes());
      }
      last = update.report;
      (*streamer)->acknowledge(result);
      if (last.coverage_desired == 1 && last.uploads == 0 && last.queue_length == 0 &&
          last.in_flight == 0)
        break;
    }
    EXPECT_GT(delivered, 0u);
    EXPECT_EQ(last.tiles_transcoded_total, 0u);
  }
}

INSTANTIATE_TEST_SUITE_P(Codecs, BlockStreamerTest,
                         testing::Values(Codec::kBc1, Codec::kBc7, Codec::kZstd, Codec::kJpeg),
                         [](const testing::TestParamInfo<Codec>& param_info) {
                           return std::string(codecName(param_info.param));
                         });

}  // namespace
}  // namespace tessera
