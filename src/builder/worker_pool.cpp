#include "worker_pool.h"

namespace tessera::detail {

WorkerPool::WorkerPool(uint32_t threads, size_t max_queued)
    : max_queued_(max_queued == 0 ? 1 : max_queued) {
  if (threads == 0) threads = 1;
  for (uint32_t i = 0; i < threads; ++i) {
    states_.push_back(std::make_unique<WorkerState>());
    states_.back()->index = i;
  }
  for (uint32_t i = 0; i < threads; ++i) workers_.emplace_back([this, i] { run(*states_[i]); });
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
