// The encoder pool: every job runs once on a worker with its own state, waitIdle waits, and
// the bounded queue holds the producer back. Ordering is proved with gates and counters.
#include "builder/worker_pool.h"

#include <atomic>
#include <condition_variable>
#include <mutex>
#include <set>
#include <thread>

#include <gtest/gtest.h>

namespace tessera::detail {
namespace {

// A one-shot gate jobs can wait on; open() releases every waiter.
class Gate {
 public:
  void open() {
    {
      std::lock_guard lock(mutex_);
      open_ = true;
    }
    changed_.notify_all();
  }
  void wait() {
    std::unique_lock lock(mutex_);
    changed_.wait(lock, [&] { return open_; });
  }
  bool isOpen() {
    std::lock_guard lock(mutex_);
    return open_;
  }

 private:
  std::mutex mutex_;  // guards open_
  std::condition_variable changed_;
  bool open_ = false;
};

TEST(WorkerPool, RunsEveryJobExactlyOnce) {
  constexpr int kJobs = 2000;
  std::vector<std::atomic<int>> runs(kJobs);
  WorkerPool pool(3, 4);
  for (int i = 0; i < kJobs; ++i) pool.submit([&runs, i](WorkerState&) { ++runs[i]; });
  pool.waitIdle();
  for (int i = 0; i < kJobs; ++i) ASSERT_EQ(runs[i].load(), 1) << "job " << i;
}

TEST(WorkerPool, StartGivesAPoolThatRunsEveryJob) {
  auto pool = WorkerPool::start(3, 4);
  ASSERT_TRUE(pool) << pool.error().message;
  EXPECT_EQ((*pool)->threadCount(), 3u);
  std::atomic<int> runs{0};
  for (int i = 0; i < 50; ++i) (*pool)->submit([&](WorkerState&) { ++runs; });
  (*pool)->waitIdle();
  EXPECT_EQ(runs.load(), 50);
}

TEST(WorkerPool, WaitIdleReturnsOnlyAfterRunningJobsFinish) {
  WorkerPool pool(2, 8);
  Gate gate;
  std::atomic<int> finished{0};
  for (int i = 0; i < 6; ++i) {
    pool.submit([&](WorkerState&) {
      gate.wait();
      ++finished;
    });
  }
  std::thread opener([&] { gate.open(); });
  pool.waitIdle();
  EXPECT_TRUE(gate.isOpen());
  EXPECT_EQ(finished.load(), 6);
  opener.join();
}

TEST(WorkerPool, WaitIdleOnAnIdlePoolReturns) {
  WorkerPool pool(2, 2);
  pool.waitIdle();
  pool.waitIdle();
  SUCCEED();
}

TEST(WorkerPool, ABoundedQueueBlocksTheProducerUntilAJobFinishes) {
  WorkerPool pool(1, 2);
  Gate gate, started;
  std::atomic<int> finished{0};
  // The only worker takes this job and holds it until the gate opens.
  pool.submit([&](WorkerState&) {
    started.open();
    gate.wait();
    ++finished;
  });
  started.wait();
  // Two more fill the queue; a fourth cannot be queued until the first job ends.
  pool.submit([&](WorkerState&) { ++finished; });
  pool.submit([&](WorkerState&) { ++finished; });
  std::atomic<bool> gate_open_when_queued{false};
  std::thread producer([&] {
    pool.submit([&](WorkerState&) { ++finished; });
    gate_open_when_queued = gate.isOpen();
  });
  gate.open();
  producer.join();
  EXPECT_TRUE(gate_open_when_queued.load());
  pool.waitIdle();
  EXPECT_EQ(finished.load(), 4);
}

TEST(WorkerPool, EachWorkerKeepsItsOwnState) {
  WorkerPool pool(4, 8);
  ASSERT_EQ(pool.threadCount(), 4u);
  std::mutex mutex;  // guards seen
  std::set<std::pair<uint32_t, std::thread::id>> seen;
  std::atomic<int> bad_index{0};
  for (int i = 0; i < 400; ++i) {
    pool.submit([&](WorkerState& state) {
      if (state.index >= 4) ++bad_index;
      std::lock_guard lock(mutex);
      seen.insert({state.index, std::this_thread::get_id()});
    });
  }
  pool.waitIdle();
  EXPECT_EQ(bad_index.load(), 0);
  // One thread per index: no index was used from two threads, no thread used two indexes.
  std::set<uint32_t> indexes;
  std::set<std::thread::id> threads;
  for (const auto& [index, thread] : seen) {
    EXPECT_TRUE(indexes.insert(index).second) << "index " << index << " on two threads";
    EXPECT_TRUE(threads.insert(thread).second) << "a thread with two indexes";
  }
  for (uint32_t i = 0; i < 4; ++i) EXPECT_EQ(pool.state(i).index, i);
}

TEST(WorkerPool, ZeroThreadsAndZeroQueueStillRunJobs) {
  WorkerPool pool(0, 0);
  EXPECT_EQ(pool.threadCount(), 1u);
  std::atomic<int> runs{0};
  for (int i = 0; i < 10; ++i) pool.submit([&](WorkerState&) { ++runs; });
  pool.waitIdle();
  EXPECT_EQ(runs.load(), 10);
}

TEST(WorkerPool, DestructionDrainsQueuedJobs) {
  std::atomic<int> runs{0};
  {
    WorkerPool pool(2, 64);
    for (int i = 0; i < 50; ++i) pool.submit([&](WorkerState&) { ++runs; });
  }
  EXPECT_EQ(runs.load(), 50);
}

}  // namespace
}  // namespace tessera::detail
