// The link estimator on synthetic samples (times passed in, no clock), the link model parser,
// and the simulated link: its bytes, its lower bound on time (a model can be slower on a
// loaded machine, never faster), fair sharing and cancellation.
#include <tessera/link.h>

#include <future>
#include <numeric>
#include <thread>

#include <gtest/gtest.h>

namespace tessera {
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

TEST(LinkModelTest, ParsesRatesAndRoundTripsWithUnits) {
  auto a = parseLinkModel("20mbit:40ms");
  ASSERT_TRUE(a) << a.error().message;
  EXPECT_DOUBLE_EQ(a->bits_per_s, 20e6);
  EXPECT_DOUBLE_EQ(a->rtt_s, 0.040);
  auto b = parseLinkModel("2Mbit:150ms");
  ASSERT_TRUE(b);
  EXPECT_DOUBLE_EQ(b->bits_per_s, 2e6);
  EXPECT_DOUBLE_EQ(b->rtt_s, 0.150);
  auto c = parseLinkModel("500kbit:0.3s");
  ASSERT_TRUE(c);
  EXPECT_DOUBLE_EQ(c->bits_per_s, 500e3);
  EXPECT_DOUBLE_EQ(c->rtt_s, 0.3);
  auto d = parseLinkModel("1gbit:250us");
  ASSERT_TRUE(d);
  EXPECT_DOUBLE_EQ(d->bits_per_s, 1e9);
  EXPECT_DOUBLE_EQ(d->rtt_s, 250e-6);
}

TEST(LinkModelTest, RejectsMalformedTextNamingIt) {
  for (const char* text : {"20mbit", "fast:40ms", "20mbit:40", "20:40ms", "0mbit:1ms", "-5mbit:1ms",
                           "20mbit:-1ms", "20mbit:11s", "", "nanmbit:1ms"}) {
    auto parsed = parseLinkModel(text);
    ASSERT_FALSE(parsed) << text;
    EXPECT_EQ(parsed.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(parsed.error().message.find(std::string("'") + text + "'"), std::string::npos)
        << parsed.error().message;
  }
}

std::vector<uint8_t> pattern(size_t n) {
  std::vector<uint8_t> bytes(n);
  for (size_t i = 0; i < n; ++i) bytes[i] = uint8_t(i * 7 + 3);
  return bytes;
}

double secondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

TEST(ThrottledSourceTest, DeliversTheInnerBytesNoSoonerThanTheLinkAllows) {
  auto inner = makeMemorySource(pattern(200'000), "mem:link");
  auto link = makeThrottledSource(inner, {2e6, 0.020});  // 250 kB/s
  std::vector<uint8_t> out(50'000);
  const auto start = Clock::now();
  ASSERT_TRUE(link->read(1000, out));
  const double took = secondsSince(start);
  EXPECT_GE(took, 0.020 + 50'000 / 250e3 - 0.002);  // round trip + transfer
  EXPECT_LT(took, 10);                              // generous: a loaded machine
  std::vector<uint8_t> expected(out.size());
  ASSERT_TRUE(inner->read(1000, expected));
  EXPECT_EQ(out, expected);
  LinkStatsTotal totals = link->totals();
  EXPECT_EQ(totals.reads, 1u);
  EXPECT_EQ(totals.bytes, 50'000u);
  EXPECT_EQ(totals.reads_cancelled, 0u);
  EXPECT_NE(link->name().find("mem:link"), std::string::npos);
}

TEST(ThrottledSourceTest, ReadsInParallelShareTheRate) {
  // Four reads of 25 kB at once on a 250 kB/s link: 100 kB cross in no less than 0.4 s,
  // whatever the parallelism (round trips overlap, bandwidth does not add up).
  auto link = makeThrottledSource(makeMemorySource(pattern(200'000), "mem:link"), {2e6, 0.010});
  const auto start = Clock::now();
  std::vector<std::future<bool>> reads;
  for (int i = 0; i < 4; ++i)
    reads.push_back(std::async(std::launch::async, [&, i] {
      std::vector<uint8_t> out(25'000);
      return bool(link->read(uint64_t(i) * 25'000, out));
    }));
  for (auto& read : reads) EXPECT_TRUE(read.get());
  const double took = secondsSince(start);
  EXPECT_GE(took, 100'000 / 250e3 - 0.002);
  EXPECT_LT(took, 10);
  EXPECT_EQ(link->totals().bytes, 100'000u);
}

TEST(ThrottledSourceTest, ACancelledReadStopsEarlyAndCountsOnlyWhatCrossed) {
  // 8 MB at 1 Mbit/s would take over a minute; the flag set while it waits ends it.
  auto link = makeThrottledSource(makeMemorySource(pattern(8'000'000), "mem:link"), {1e6, 0.050});
  std::atomic<bool> cancel{false};
  const auto start = Clock::now();
  auto read = std::async(std::launch::async, [&] {
    std::vector<uint8_t> out(8'000'000);
    return link->readCancellable(0, out, cancel);
  });
  cancel.store(true);
  Result<void> result = read.get();
  ASSERT_FALSE(result);
  EXPECT_EQ(result.error().code, ErrorCode::kCancelled);
  EXPECT_NE(result.error().message.find("mem:link"), std::string::npos);
  EXPECT_LT(secondsSince(start), 10);
  LinkStatsTotal totals = link->totals();
  EXPECT_EQ(totals.reads_cancelled, 1u);
  EXPECT_LT(totals.bytes, 8'000'000u);
}

TEST(ThrottledSourceTest, ARangePastTheEndFailsAtOnceWithoutUsingTheLink) {
  auto link = makeThrottledSource(makeMemorySource(pattern(1000), "mem:short"), {1e3, 5});
  std::vector<uint8_t> out(100);
  const auto start = Clock::now();
  Result<void> result = link->read(950, out);
  ASSERT_FALSE(result);
  EXPECT_LT(secondsSince(start), 4);  // the 5 s round trip was not waited
  EXPECT_EQ(link->totals().reads, 0u);
}

}  // namespace
}  // namespace tessera
