// The link estimator on synthetic samples (times passed in, no clock): throughput over busy
// time, latency as a min-filter, queue wait.
#include "stream/link_estimator.h"

#include <gtest/gtest.h>

namespace tessera::detail {
namespace {

using Clock = std::chrono::steady_clock;

Clock::time_point at(double s) {
  return Clock::time_point{} +
         std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1000 + s));
}

/// A read alone on a link of `rate` bytes/s and `latency` s, starting at `t`; returns its end.
double oneRead(LinkEstimator& e, double t, uint64_t bytes, double rate, double latency) {
  const double end = t + latency + double(bytes) / rate;
  e.readStarted(at(t));
  e.readFinished(at(t), at(end), bytes);
  return end;
}

TEST(LinkEstimatorTest, NothingMeasuredGivesNoEstimate) {
  LinkEstimator e;
  LinkEstimate estimate = e.estimate();
  EXPECT_EQ(estimate.reads, 0u);
  EXPECT_EQ(estimate.bytes_per_s, 0);
  EXPECT_EQ(estimate.bytesWithin(10), 0);
}

TEST(LinkEstimatorTest, ConvergesOnTheRateOfBackToBackReads) {
  LinkEstimator e;
  double t = 0;
  for (int i = 0; i < 50; ++i) t = oneRead(e, t, 100'000, 1e6, 0);
  LinkEstimate estimate = e.estimate();
  EXPECT_NEAR(estimate.bytes_per_s, 1e6, 1e6 * 0.01);
  EXPECT_EQ(estimate.reads, 50u);
  EXPECT_EQ(estimate.bytes, 5'000'000u);
}

TEST(LinkEstimatorTest, ReadsInParallelAddUpToTheLinkRate) {
  // Four reads at once share a 1 MB/s link: each takes 0.4 s for 100 kB. Charging each its
  // whole duration would estimate 250 kB/s; the link delivered 1 MB/s.
  LinkEstimator e;
  double t = 0;
  for (int round = 0; round < 20; ++round) {
    for (int i = 0; i < 4; ++i) e.readStarted(at(t));
    for (int i = 0; i < 4; ++i) e.readFinished(at(t), at(t + 0.4), 100'000);
    t += 0.4;
  }
  EXPECT_NEAR(e.estimate().bytes_per_s, 1e6, 1e6 * 0.01);
}

TEST(LinkEstimatorTest, IdleTimeNeitherLowersNorAgesTheEstimate) {
  LinkEstimator e;
  double t = 0;
  for (int i = 0; i < 20; ++i) t = oneRead(e, t, 50'000, 2e6, 0);
  const double before = e.estimate().bytes_per_s;
  t += 60;  // a minute with nothing to read
  t = oneRead(e, t, 50'000, 2e6, 0);
  EXPECT_NEAR(e.estimate().bytes_per_s, before, before * 0.01);
  EXPECT_NEAR(before, 2e6, 2e6 * 0.01);
}

TEST(LinkEstimatorTest, FollowsARateChangeWithinAFewWindows) {
  LinkEstimator::Options options;
  options.window_s = 1;
  LinkEstimator e(options);
  double t = 0;
  for (int i = 0; i < 40; ++i) t = oneRead(e, t, 100'000, 1e6, 0);  // 4 s at 1 MB/s
  EXPECT_NEAR(e.estimate().bytes_per_s, 1e6, 1e4);
  // The link slows to 250 kB/s: 0.4 s a read. After one window the estimate is between the
  // two; after five it is within 2% of the new rate.
  for (int i = 0; i < 3; ++i) t = oneRead(e, t, 100'000, 250e3, 0);
  const double mid = e.estimate().bytes_per_s;
  EXPECT_LT(mid, 0.9e6);
  EXPECT_GT(mid, 260e3);
  for (int i = 0; i < 12; ++i) t = oneRead(e, t, 100'000, 250e3, 0);
  EXPECT_NEAR(e.estimate().bytes_per_s, 250e3, 250e3 * 0.02);
}

TEST(LinkEstimatorTest, LatencyIsBoundedByTheShortestRecentRead) {
  // 40 ms round trip on a 2.5 MB/s link; reads from 2 kB to 400 kB, one at a time. The
  // rate is what one reader achieves, round trips included: 810 kB per 0.564 s.
  LinkEstimator e;
  double t = 0;
  const uint64_t sizes[] = {2'000, 400'000, 30'000, 120'000, 8'000, 250'000};
  for (int round = 0; round < 5; ++round)
    for (uint64_t bytes : sizes) t = oneRead(e, t, bytes, 2.5e6, 0.040);
  LinkEstimate estimate = e.estimate();
  EXPECT_GE(estimate.latency_s, 0.040);
  EXPECT_LT(estimate.latency_s, 0.0409);  // the 2 kB read: 40 ms and 0.8 ms of transfer
  EXPECT_NEAR(estimate.bytes_per_s, 810e3 / 0.564, 810e3 / 0.564 * 0.01);
  // What can arrive within a second: (1 - latency) at the rate.
  EXPECT_NEAR(estimate.bytesWithin(1.0), estimate.bytes_per_s * (1 - estimate.latency_s), 1);
  EXPECT_EQ(estimate.bytesWithin(0.01), 0);
  // The latency window slides: once the small reads are out of it, the shortest is 8 kB's.
  for (int i = 0; i < 40; ++i) t = oneRead(e, t, 8'000, 2.5e6, 0.040);
  EXPECT_NEAR(e.estimate().latency_s, 0.040 + 8e3 / 2.5e6, 1e-6);
}

TEST(LinkEstimatorTest, AbandonedReadsAddTimeButNoSample) {
  LinkEstimator e;
  double t = oneRead(e, 0, 100'000, 1e6, 0);
  e.readStarted(at(t));
  e.readFinished(at(t), at(t + 0.5), 0);  // cancelled: half a second, no bytes
  EXPECT_EQ(e.estimate().reads, 1u);
  t += 0.5;
  t = oneRead(e, t, 100'000, 1e6, 0);
  LinkEstimate estimate = e.estimate();
  EXPECT_EQ(estimate.reads, 2u);
  // 200 kB over 0.7 s busy: the abandoned read's time is charged, so the estimate is low,
  // never high.
  EXPECT_LT(estimate.bytes_per_s, 1e6);
  EXPECT_GT(estimate.bytes_per_s, 200e3 / 0.7 * 0.9);
}

TEST(LinkEstimatorTest, QueueWaitAveragesRecentTiles) {
  LinkEstimator e;
  for (int i = 0; i < 100; ++i) e.queueWait(std::chrono::milliseconds(100));
  EXPECT_NEAR(e.estimate().queue_wait_s, 0.1, 1e-6);
  for (int i = 0; i < 100; ++i) e.queueWait(std::chrono::milliseconds(10));
  EXPECT_NEAR(e.estimate().queue_wait_s, 0.01, 1e-3);
}

}  // namespace
}  // namespace tessera::detail
