// The I/O fault loop (issue 31): a streamer over a source that fails reads at random (I/O
// errors, timeouts, short reads that claim success, flipped bytes) while the view jumps and
// pans. Every tile the renderer receives must equal its clean decode (a torn tile never
// reaches the screen), and once the faults stop every view loads to full detail (loading
// recovers). Run for a lossy codec and for ptm, whose tiles decode against their parents.
#include <tessera/stream.h>

#include <map>
#include <mutex>
#include <random>
#include <tuple>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include "support/synthetic_archive.h"

namespace tessera {
namespace {

/// Wraps a healthy source; while faulting, each read fails one time in `1 / probability` in a
/// random way. Thread-safe (reads come from the loader threads).
class RandomFaultSource final : public ByteSource {
 public:
  RandomFaultSource(std::shared_ptr<ByteSource> inner, uint32_t seed)
      : inner_(std::move(inner)), random_(seed) {}

  uint64_t sizeBytes() const override { return inner_->sizeBytes(); }
  const std::string& name() const override { return inner_->name(); }

  Result<void> read(uint64_t offset_bytes, std::span<uint8_t> out) const override {
    int fault = 0;
    size_t flip_at = 0;
    {
      std::lock_guard lock(mutex_);
      if (faulting_ && std::uniform_real_distribution<double>(0, 1)(random_) < probability_) {
        fault = 1 + int(random_() % 4);
        flip_at = out.empty() ? 0 : size_t(random_() % out.size());
        ++faults_;
      }
    }
    switch (fault) {
      case 1:
        return fail(ErrorCode::kIo,
                    fmt::format("{}: read at {} failed: Input/output error", name(), offset_bytes));
      case 2:
        return fail(ErrorCode::kIo,
                    fmt::format("{}: read at {} timed out (ETIMEDOUT)", name(), offset_bytes));
      case 3: {  // a short read that claims success: the tail is whatever was there
        TESSERA_TRY(inner_->read(offset_bytes, out.first(out.size() / 2)));
        std::fill(out.begin() + std::ptrdiff_t(out.size() / 2), out.end(), uint8_t{0});
        return {};
      }
      case 4:  // bytes torn in transit
        TESSERA_TRY(inner_->read(offset_bytes, out));
        if (!out.empty()) out[flip_at] ^= 0x5A;
        return {};
      default: return inner_->read(offset_bytes, out);
    }
  }

  void setFaulting(bool faulting, double probability) {
    std::lock_guard lock(mutex_);
    faulting_ = faulting;
    probability_ = probability;
  }
  uint64_t faults() const {
    std::lock_guard lock(mutex_);
    return faults_;
  }

 private:
  std::shared_ptr<ByteSource> inner_;
  mutable std::mutex mutex_;  // guards everything below
  mutable std::mt19937 random_;
  bool faulting_ = false;
  double probability_ = 0;
  mutable uint64_t faults_ = 0;
};

using Key = std::tuple<uint32_t, uint32_t, uint32_t, uint32_t>;

class FaultLoop : public testing::TestWithParam<Codec> {
 protected:
  void SetUp() override {
    test::SyntheticArchiveSpec spec;
    spec.codec = GetParam();
    spec.width_px = 2048;
    spec.height_px = 1536;
    const std::vector<uint8_t>& bytes = test::syntheticArchiveBytes(spec);
    ASSERT_FALSE(bytes.empty());
    clean_ = test::openArchiveOrFail(makeMemorySource(bytes, "mem:clean.tess"));
    faulty_source_ = std::make_shared<RandomFaultSource>(makeMemorySource(bytes, "mem:faulty.tess"),
                                                         /*seed=*/uint32_t(GetParam()) + 7);
    faulty_ = test::openArchiveOrFail(faulty_source_);
    ASSERT_TRUE(clean_ && faulty_);
  }

  /// The clean decode of a tile, decoded once.
  const Image& reference(const TileId& id) {
    const Key key{id.image, id.level, id.x, id.y};
    auto it = reference_.find(key);
    if (it == reference_.end()) {
      Result<Image> tile = clean_->readTile(id);
      EXPECT_TRUE(tile) << tile.error().message;
      it = reference_.emplace(key, tile ? std::move(*tile) : Image{}).first;
    }
    return it->second;
  }

  /// One frame: every upload is compared with its clean decode, then accepted.
  FrameReport frame(TileStreamer& streamer, const View& view) {
    const FrameUpdate& update = streamer.update(view);
    ApplyResult result;
    for (const auto& tile : update.uploads) {
      const Image& clean = reference(tile->id);
      EXPECT_EQ(tile->texels.texels, clean.texels)
          << "tile (" << tile->id.level << "," << tile->id.x << "," << tile->id.y
          << ") reached the renderer torn";
      result.accepted.push_back(tile->id);
    }
    const FrameReport report = update.report;
    streamer.acknowledge(result);
    return report;
  }

  std::shared_ptr<Archive> clean_;
  std::shared_ptr<RandomFaultSource> faulty_source_;
  std::shared_ptr<Archive> faulty_;
  std::map<Key, Image> reference_;
};

View randomView(std::mt19937& random, const ImageInfo& info) {
  View view;
  view.ortho.centre_x = std::uniform_real_distribution<double>(0, info.width_px)(random);
  view.ortho.centre_y = std::uniform_real_distribution<double>(0, info.height_px)(random);
  view.ortho.texels_per_pixel = std::exp2(std::uniform_real_distribution<double>(-1, 3)(random));
  view.ortho.viewport_w = 320;
  view.ortho.viewport_h = 240;
  return view;
}

TEST_P(FaultLoop, TornTilesNeverReachTheRendererAndLoadingRecovers) {
  StreamerOptions options;
  options.loader_threads = 2;
  options.cache_budget_bytes = size_t(32) << 20;
  options.retry_initial = std::chrono::milliseconds(1);
  options.retry_max = std::chrono::milliseconds(4);
  Result<std::unique_ptr<TileStreamer>> created = TileStreamer::create(faulty_, options);
  ASSERT_TRUE(created) << created.error().message;
  TileStreamer& streamer = **created;
  const ImageInfo& info = faulty_->images()[0];
  std::mt19937 random(11);

  // Jumps and pans under faults: one read in five fails.
  faulty_source_->setFaulting(true, 0.2);
  View view = randomView(random, info);
  for (int step = 0; step < 400; ++step) {
    if (step % 40 == 0) view = randomView(random, info);  // a jump
    view.ortho.centre_x += 9;                             // a pan
    frame(streamer, view);
    if (step % 8 == 0) streamer.waitIdleForTesting();  // let loads finish, faults included
  }
  EXPECT_GT(faulty_source_->faults(), 20u) << "the loop injected too few faults to mean much";

  // Faults stop: every view settles at full detail.
  faulty_source_->setFaulting(false, 0);
  for (int jump = 0; jump < 5; ++jump) {
    const View settled = randomView(random, info);
    FrameReport report;
    for (int i = 0; i < 200; ++i) {
      streamer.waitIdleForTesting();
      report = frame(streamer, settled);
      if (report.coverage_desired == 1 && report.uploads == 0 && report.queue_length == 0 &&
          report.in_flight == 0)
        break;
    }
    EXPECT_EQ(report.coverage_desired, 1) << "jump " << jump << " did not recover full detail";
  }
}

INSTANTIATE_TEST_SUITE_P(Codecs, FaultLoop, testing::Values(Codec::kJpeg, Codec::kPtm),
                         [](const testing::TestParamInfo<Codec>& param) {
                           return std::string(codecName(param.param));
                         });

}  // namespace
}  // namespace tessera
