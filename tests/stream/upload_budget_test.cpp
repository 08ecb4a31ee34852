// The adaptive upload budget, fed made-up timings (no GPU, no clock): it follows the measured
// rate, smooths it, stays within its clamps, ignores frames that uploaded nothing, and keeps
// a fixed budget when adaptation is off.
#include "stream/upload_budget.h"

#include <limits>

#include <gtest/gtest.h>

namespace tessera::detail {
namespace {

constexpr uint64_t kMiB = uint64_t(1) << 20;

ResidencyOptions adaptiveOptions() {
  ResidencyOptions options;
  AdaptiveUploadOptions& a = options.adaptive_upload;
  a.enabled = true;
  a.frame_ms = 20;
  a.upload_share = 0.25;  // 5 ms of uploads a frame
  a.min_bytes = kMiB;
  a.max_bytes = 64 * kMiB;
  a.initial_bytes_per_ms = 256 * 1024;
  a.smoothing = 0.5;
  return options;
}

TEST(UploadBudget, StartsFromTheInitialRateBeforeAnyMeasurement) {
  UploadBudgetController budget(adaptiveOptions());
  EXPECT_EQ(budget.samples(), 0u);
  EXPECT_EQ(budget.budgetBytes(), 5 * 256 * 1024u);  // 256 KiB/ms for 5 ms
}

TEST(UploadBudget, TheFirstMeasurementReplacesTheInitialGuess) {
  UploadBudgetController budget(adaptiveOptions());
  budget.observe(4 * kMiB, 2);  // 2 MiB/ms
  EXPECT_DOUBLE_EQ(budget.bytesPerMs(), 2.0 * kMiB);
  EXPECT_EQ(budget.budgetBytes(), 10 * kMiB);
}

TEST(UploadBudget, ASlowRendererGetsASmallBudgetAndAFastOneALargeOne) {
  UploadBudgetController slow(adaptiveOptions());
  UploadBudgetController fast(adaptiveOptions());
  for (int frame = 0; frame < 20; ++frame) {
    slow.observe(2 * kMiB, 8);     // 256 KiB/ms: a software renderer under load
    fast.observe(16 * kMiB, 0.5);  // 32 MiB/ms: a memcpy into mapped memory
  }
  EXPECT_EQ(slow.budgetBytes(), 5 * 256 * 1024u);
  EXPECT_EQ(fast.budgetBytes(), 64 * kMiB) << "clamped to max_bytes";
}

TEST(UploadBudget, SmoothsARunOfSlowFramesInsteadOfJumpingToThem) {
  UploadBudgetController budget(adaptiveOptions());
  budget.observe(4 * kMiB, 1);  // 4 MiB/ms
  const uint64_t before = budget.budgetBytes();
  budget.observe(4 * kMiB, 9);  // one frame nine times slower
  const uint64_t after_one = budget.budgetBytes();
  // Half weight: bytes stay 4 MiB, ms become 5: 0.8 MiB/ms, between the two rates.
  EXPECT_DOUBLE_EQ(budget.bytesPerMs(), 4.0 * kMiB / 5);
  EXPECT_LT(after_one, before);
  EXPECT_GT(after_one, 5 * 4 * kMiB / 9);
  for (int frame = 0; frame < 30; ++frame) budget.observe(4 * kMiB, 9);
  EXPECT_NEAR(budget.bytesPerMs(), 4.0 * kMiB / 9, 1.0) << "converges to the new rate";
}

TEST(UploadBudget, LargeFramesWeighMoreThanSmallOnes) {
  UploadBudgetController budget(adaptiveOptions());
  budget.observe(8 * kMiB, 4);  // 2 MiB/ms
  // A tiny frame whose time is mostly fixed cost: 64 KiB in 1 ms. The ratio of smoothed sums
  // moves far less than a smoothed ratio would (0.5 * 2 MiB + 0.5 * 64 KiB = 1.03 MiB/ms).
  budget.observe(64 * 1024, 1);
  EXPECT_GT(budget.bytesPerMs(), 1.5 * kMiB);
}

TEST(UploadBudget, FramesWithoutUploadsOrWithBogusTimesAreIgnored) {
  UploadBudgetController budget(adaptiveOptions());
  budget.observe(4 * kMiB, 2);
  const double rate = budget.bytesPerMs();
  budget.observe(0, 30);
  budget.observe(kMiB, -1);
  budget.observe(kMiB, std::numeric_limits<double>::quiet_NaN());
  budget.observe(kMiB, std::numeric_limits<double>::infinity());
  EXPECT_EQ(budget.samples(), 1u);
  EXPECT_DOUBLE_EQ(budget.bytesPerMs(), rate);
}

TEST(UploadBudget, AZeroTimeCountsAsAMicrosecondAndHitsTheCeiling) {
  UploadBudgetController budget(adaptiveOptions());
  budget.observe(kMiB, 0);
  EXPECT_EQ(budget.budgetBytes(), 64 * kMiB);
}

TEST(UploadBudget, NeverFallsBelowTheFloor) {
  UploadBudgetController budget(adaptiveOptions());
  budget.observe(64 * 1024, 500);  // 128 bytes/ms
  EXPECT_EQ(budget.budgetBytes(), kMiB);
}

TEST(UploadBudget, FollowsTheFrameTimeTarget) {
  ResidencyOptions options = adaptiveOptions();
  options.adaptive_upload.frame_ms = 1000.0 / 30;
  UploadBudgetController at_30(options);
  options.adaptive_upload.frame_ms = 1000.0 / 120;
  UploadBudgetController at_120(options);
  for (UploadBudgetController* budget : {&at_30, &at_120}) budget->observe(2 * kMiB, 2);
  EXPECT_NEAR(double(at_30.budgetBytes()), 4.0 * double(at_120.budgetBytes()), 4.0);
}

TEST(UploadBudget, AFixedBudgetIgnoresMeasurements) {
  ResidencyOptions options = adaptiveOptions();
  options.adaptive_upload.enabled = false;
  options.upload_budget_bytes = 16 * kMiB;
  UploadBudgetController budget(options);
  budget.observe(kMiB, 100);
  EXPECT_EQ(budget.budgetBytes(), 16 * kMiB);
  options.upload_budget_bytes = 0;
  EXPECT_EQ(UploadBudgetController(options).budgetBytes(), 0u) << "0: no byte limit";
}

}  // namespace
}  // namespace tessera::detail
