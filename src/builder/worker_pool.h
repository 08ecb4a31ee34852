#pragma once
// A fixed pool of encoder threads fed by a bounded FIFO (libvips' threadpool model: work units
// are produced serially and worked on in parallel). Each worker owns a WorkerState that is
// passed to every job it runs, so per-thread scratch is explicit, never a hidden global.

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include <tessera/result.h>

#include "codecs/decode.h"

namespace tessera::detail {

/// Per-worker state. Owned by one worker thread while it runs jobs; read by the pool's owner
/// only after waitIdle().
struct WorkerState {
  uint32_t index = 0;
  CodecScratch codec_scratch;
  /// The stored tile a job cuts out of a band before encoding it; sized by the pool's owner
  /// while idle, so jobs never allocate it.
  std::vector<uint8_t> tile_texels;
};

/// Thread-safe for submit/waitIdle from one producer thread.
class WorkerPool {
 public:
  using Job = std::function<void(WorkerState&)>;

  /// Starts `threads` workers (at least 1). `max_queued` bounds jobs waiting to run;
  /// submit blocks beyond it, which bounds the memory held by queued work. The system must be
  /// able to start them (a contract: TESSERA_CHECK); start() is the fallible form.
  WorkerPool(uint32_t threads, size_t max_queued);
  /// The same, but a thread the system refuses (EAGAIN: too many threads or too little memory
  /// for their stacks) fails with kTooLarge naming how many were asked for and how many
  /// started; the ones that started are joined first.
  [[nodiscard]] static Result<std::unique_ptr<WorkerPool>> start(uint32_t threads,
                                                                 size_t max_queued);
  /// Drains the queue, then joins the workers.
  ~WorkerPool();
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  void submit(Job job);
  /// Blocks until every submitted job has finished.
  void waitIdle();
  uint32_t threadCount() const { return uint32_t(workers_.size()); }
  /// Valid only while idle (after waitIdle()).
  WorkerState& state(uint32_t index) { return *states_[index]; }

 private:
  struct Unstarted {};
  WorkerPool(Unstarted, size_t max_queued);
  /// Starts the workers; on a refusal stops and joins those started and returns its message.
  std::string startWorkers(uint32_t threads);
  void run(WorkerState& state);

  std::mutex mutex_;  // guards queue_, running_ and stopping_
  std::condition_variable work_ready_;
  std::condition_variable space_or_idle_;
  std::deque<Job> queue_;
  size_t max_queued_;
  size_t running_ = 0;
  bool stopping_ = false;
  std::vector<std::unique_ptr<WorkerState>> states_;
  std::vector<std::thread> workers_;
};

}  // namespace tessera::detail
