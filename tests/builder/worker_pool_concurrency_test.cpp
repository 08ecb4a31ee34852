// Stress for the encoder pool, run under ThreadSanitizer in CI (label "concurrency").
#include <atomic>
#include <vector>

#include <gtest/gtest.h>

#include "builder/worker_pool.h"

namespace tessera::detail {
namespace {

TEST(WorkerPoolStress, ManyTinyJobsThroughATinyQueue) {
  constexpr int kJobs = 50000;
  std::vector<uint8_t> runs(kJobs, 0);  // each job writes only its own slot
  std::atomic<uint64_t> sum{0};
  {
    WorkerPool pool(8, 2);
    for (int round = 0; round < 5; ++round) {
      for (int i = round * kJobs / 5; i < (round + 1) * kJobs / 5; ++i) {
        pool.submit([&, i](WorkerState& state) {
          ++runs[i];
          sum += uint64_t(i) + state.index * 0;
        });
      }
      pool.waitIdle();
    }
  }
  for (int i = 0; i < kJobs; ++i) ASSERT_EQ(runs[i], 1) << i;
  EXPECT_EQ(sum.load(), uint64_t(kJobs) * (kJobs - 1) / 2);
}

TEST(WorkerPoolStress, PerWorkerStateIsNeverShared) {
  WorkerPool pool(6, 3);
  std::vector<std::atomic<int>> in_use(pool.threadCount());
  std::atomic<int> overlaps{0};
  for (int i = 0; i < 20000; ++i) {
    pool.submit([&](WorkerState& state) {
      if (in_use[state.index].fetch_add(1) != 0) ++overlaps;
      in_use[state.index].fetch_sub(1);
    });
  }
  pool.waitIdle();
  EXPECT_EQ(overlaps.load(), 0);
}

}  // namespace
}  // namespace tessera::detail
