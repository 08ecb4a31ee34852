#include "worker_pool.h"

#include <system_error>

#include <fmt/format.h>

#include <tessera/check.h>

namespace tessera::detail {

WorkerPool::WorkerPool(Unstarted, size_t max_queued)
    : max_queued_(max_queued == 0 ? 1 : max_queued) {}

WorkerPool::WorkerPool(uint32_t threads, size_t max_queued) : WorkerPool(Unstarted{}, max_queued) {
  const std::string refused = startWorkers(threads);
  TESSERA_CHECK(refused.empty()) << refused;
}

Result<std::unique_ptr<WorkerPool>> WorkerPool::start(uint32_t threads, size_t max_queued) {
  std::unique_ptr<WorkerPool> pool(new WorkerPool(Unstarted{}, max_queued));
  const std::string refused = pool->startWorkers(threads);
  if (!refused.empty()) return fail(ErrorCode::kTooLarge, refused);
  return pool;
}

std::string WorkerPool::startWorkers(uint32_t threads) {
  if (threads == 0) threads = 1;
  for (uint32_t i = 0; i < threads; ++i) {
    states_.push_back(std::make_unique<WorkerState>());
    states_.back()->index = i;
  }
  for (uint32_t i = 0; i < threads; ++i) {
    try {
      workers_.emplace_back([this, i] { run(*states_[i]); });
    } catch (const std::system_error& e) {
      {
        std::lock_guard lock(mutex_);
        stopping_ = true;
      }
      work_ready_.notify_all();
      for (std::thread& worker : workers_) worker.join();
      workers_.clear();
      return fmt::format("cannot start {} encoder threads: the system refused thread {} ({})",
                         threads, i + 1, e.what());
    }
  }
  return "";
}

WorkerPool::~WorkerPool() {
  {
    std::unique_lock lock(mutex_);
    stopping_ = true;
  }
  work_ready_.notify_all();
  for (auto& worker : workers_) worker.join();
}

void WorkerPool::submit(Job job) {
  std::unique_lock lock(mutex_);
  space_or_idle_.wait(lock, [&] { return queue_.size() < max_queued_; });
  queue_.push_back(std::move(job));
  lock.unlock();
  work_ready_.notify_one();
}

void WorkerPool::waitIdle() {
  std::unique_lock lock(mutex_);
  space_or_idle_.wait(lock, [&] { return queue_.empty() && running_ == 0; });
}

void WorkerPool::run(WorkerState& state) {
  std::unique_lock lock(mutex_);
  for (;;) {
    work_ready_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
    if (queue_.empty()) return;  // stopping and drained
    Job job = std::move(queue_.front());
    queue_.pop_front();
    ++running_;
    lock.unlock();
    space_or_idle_.notify_all();
    job(state);
    lock.lock();
    --running_;
    if (queue_.empty() && running_ == 0) space_or_idle_.notify_all();
  }
}

}  // namespace tessera::detail
