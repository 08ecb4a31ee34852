// The staging ring's policy (RingSpans), with fences signalled by hand: bytes are reused only
// after the fence of the frame that took them has signalled, fences retire in order, a full
// ring refuses instead of waiting, and frames wrap around the end.
#include "gl/upload_ring.h"

#include <set>

#include <gtest/gtest.h>

namespace tessera::gl {
namespace {

/// Fences signalled so far (by the test, standing in for the GPU).
struct FakeGpu {
  std::set<uint64_t> done;
  std::function<bool(uint64_t)> signalled() {
    return [this](uint64_t fence) { return done.count(fence) > 0; };
  }
};

TEST(RingSpans, AnEmptyRingOffersItsWholeCapacity) {
  RingSpans ring(1000);
  EXPECT_EQ(ring.room(), 1000u);
  EXPECT_EQ(ring.take(1000), 0u);
  EXPECT_EQ(ring.room(), 0u);
  EXPECT_FALSE(ring.take(1));
}

TEST(RingSpans, NoByteIsReusedBeforeItsFenceSignals) {
  RingSpans ring(1000);
  FakeGpu gpu;
  ASSERT_EQ(ring.take(600), 0u);
  ring.close(1);
  ASSERT_EQ(ring.take(300), 600u);
  ring.close(2);
  // 100 bytes left at the end; frame 1's 600 are in flight.
  EXPECT_EQ(ring.room(), 100u);
  EXPECT_FALSE(ring.take(200)) << "would overwrite frame 1 before its fence";
  EXPECT_TRUE(ring.retire(gpu.signalled()).empty());
  EXPECT_FALSE(ring.take(200));
  gpu.done.insert(1);
  EXPECT_EQ(ring.retire(gpu.signalled()), std::vector<uint64_t>{1});
  EXPECT_EQ(ring.room(), 600u);
  const std::optional<size_t> wrapped = ring.take(500);
  ASSERT_TRUE(wrapped);
  EXPECT_EQ(*wrapped, 0u) << "wraps to the start, clear of frame 2 at [600, 900)";
}

TEST(RingSpans, FencesRetireInOrderOnly) {
  RingSpans ring(1000);
  FakeGpu gpu;
  for (uint64_t frame = 1; frame <= 3; ++frame) {
    ASSERT_TRUE(ring.take(300));
    ring.close(frame);
  }
  gpu.done = {2, 3};  // reported out of order: frame 1 still holds its bytes
  EXPECT_TRUE(ring.retire(gpu.signalled()).empty());
  EXPECT_EQ(ring.framesInFlight(), 3u);
  gpu.done.insert(1);
  EXPECT_EQ(ring.retire(gpu.signalled()), (std::vector<uint64_t>{1, 2, 3}));
  EXPECT_EQ(ring.room(), 1000u);
}

TEST(RingSpans, AFullRingRefusesWithoutWaiting) {
  RingSpans ring(1000);
  ASSERT_TRUE(ring.take(400));
  ring.close(1);
  ASSERT_TRUE(ring.take(400));
  ring.close(2);
  // 200 bytes free; a frame of 300 is refused at once: the caller uploads less this frame.
  EXPECT_EQ(ring.room(), 200u);
  EXPECT_FALSE(ring.take(300));
  EXPECT_EQ(ring.take(200), 800u);
  EXPECT_EQ(ring.room(), 0u);
}

TEST(RingSpans, AFrameOfSeveralTakesIsOneFenceAndRetiresWhole) {
  RingSpans ring(1000);
  FakeGpu gpu;
  ASSERT_EQ(ring.take(100), 0u);
  ASSERT_EQ(ring.take(100), 100u);
  ring.close(7);
  ASSERT_EQ(ring.take(700), 200u);
  ring.close(8);
  EXPECT_EQ(ring.room(), 100u);
  gpu.done = {7};
  ring.retire(gpu.signalled());
  EXPECT_EQ(ring.room(), 200u) << "both takes of frame 7 are free";
  gpu.done.insert(8);
  ring.retire(gpu.signalled());
  EXPECT_EQ(ring.framesInFlight(), 0u);
  EXPECT_EQ(ring.room(), 1000u);
}

TEST(RingSpans, KeepsTakingAroundTheRingForManyFrames) {
  RingSpans ring(1000);
  FakeGpu gpu;
  // Frames of 300 bytes, the GPU two frames behind: each take lies clear of both frames in
  // flight.
  std::vector<std::pair<size_t, size_t>> in_flight;  // [begin, end) per frame, by fence
  for (uint64_t frame = 1; frame <= 50; ++frame) {
    if (frame > 2) gpu.done.insert(frame - 2);
    ring.retire(gpu.signalled());
    const std::optional<size_t> at = ring.take(300);
    ASSERT_TRUE(at) << "frame " << frame;
    for (uint64_t other = frame > 2 ? frame - 1 : 1; other < frame; ++other) {
      const auto [b, e] = in_flight[other - 1];
      EXPECT_TRUE(*at + 300 <= b || *at >= e) << "frame " << frame << " overlaps " << other;
    }
    in_flight.emplace_back(*at, *at + 300);
    ring.close(frame);
  }
}

}  // namespace
}  // namespace tessera::gl
