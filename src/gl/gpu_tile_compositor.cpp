// createGpuTileCompositor: GpuCompositor behind the reader's TileCompositor seam. A GL context
// is current on one thread at a time, and the loader threads have none, so one thread owns a
// headless context and composites the tiles handed to it, one at a time, in arrival order.
#include <condition_variable>
#include <deque>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <thread>

#include <tessera/gl.h>

namespace tessera {

namespace {

class GpuTileCompositor final : public TileCompositor {
 public:
  GpuTileCompositor() : thread_([this] { run(); }) {}
  ~GpuTileCompositor() override {
    {
      std::lock_guard lock(mutex_);
      stopping_ = true;
    }
    wake_.notify_all();
    thread_.join();
  }

  /// Waits until the thread has its context (or failed to get one).
  Result<void> started() {
    std::unique_lock lock(mutex_);
    done_.wait(lock, [&] { return started_; });
    return start_error_ ? Result<void>(fail(start_error_->code, start_error_->message))
                        : Result<void>();
  }

  Result<void> composite(const std::shared_ptr<const BrushSet>& brushes, const TileGeometry& tile,
                         std::span<const BrushInstance> instances, std::span<const TileClip> clips,
                         Image& out) override {
    // The caller waits until the job is done, so the spans and `out` outlive it.
    Result<void> result;
    bool finished = false;
    std::unique_lock lock(mutex_);
    jobs_.push_back([&] {
      result = compositeOnThread(brushes, tile, instances, clips, out);
      std::lock_guard done_lock(mutex_);
      finished = true;
    });
    wake_.notify_one();
    done_.wait(lock, [&] { return finished; });
    return result;
  }

 private:
  Result<void> compositeOnThread(const std::shared_ptr<const BrushSet>& brushes,
                                 const TileGeometry& tile, std::span<const BrushInstance> instances,
                                 std::span<const TileClip> clips, Image& out) {
    std::unique_ptr<GpuCompositor>& compositor = compositors_[brushes.get()];
    if (!compositor) {
      TESSERA_ASSIGN_OR_RETURN(compositor, GpuCompositor::create(brushes));
    }
    return compositor->compositeTile(tile, instances, out, clips);
  }

  void run() {
    Result<std::unique_ptr<GlContext>> context = GlContext::createHeadless();
    {
      std::lock_guard lock(mutex_);
      started_ = true;
      if (!context) start_error_ = context.error();
    }
    done_.notify_all();
    if (!context) return;
    for (;;) {
      std::function<void()> job;
      {
        std::unique_lock lock(mutex_);
        wake_.wait(lock, [&] { return stopping_ || !jobs_.empty(); });
        if (jobs_.empty()) break;
        job = std::move(jobs_.front());
        jobs_.pop_front();
      }
      job();
      done_.notify_all();
    }
    compositors_.clear();  // GL objects go while their context is current
  }

  std::mutex mutex_;
  std::condition_variable wake_, done_;
  std::deque<std::function<void()>> jobs_;
  bool stopping_ = false, started_ = false;
  std::optional<Error> start_error_;
  /// Thread-owned: one compositor per brush set (each keeps its set alive).
  std::map<const BrushSet*, std::unique_ptr<GpuCompositor>> compositors_;
  std::thread thread_;  // last: starts once every member above exists
};

}  // namespace

Result<std::shared_ptr<TileCompositor>> createGpuTileCompositor() {
  auto compositor = std::make_shared<GpuTileCompositor>();
  TESSERA_TRY(compositor->started());
  return std::shared_ptr<TileCompositor>(std::move(compositor));
}

}  // namespace tessera
