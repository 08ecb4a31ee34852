// The link model parser and the simulated link: its bytes, its lower bound on time (a model
// can be slower on a loaded machine, never faster), fair sharing and cancellation.
#include <tessera/link.h>

#include <chrono>
#include <future>
#include <numeric>
#include <thread>

#include <gtest/gtest.h>

namespace tessera {
namespace {

using Clock = std::chrono::steady_clock;

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
