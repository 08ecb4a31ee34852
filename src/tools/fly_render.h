#pragma once
// `tessera fly --render`: the flight drawn headless by a GPU renderer (EGL, llvmpipe without a
// GPU), with the render thread's and the GPU's time per frame, pictures at rest compared
// against the CPU reference, and the self-contained HTML report.

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <tessera/gl.h>
#include <tessera/render.h>
#include <tessera/stream.h>

namespace tessera::cli {

/// A headless context and renderer driven once per flight frame.
class FlyRenderer {
 public:
  [[nodiscard]] static Result<std::unique_ptr<FlyRenderer>> create(RendererKind kind,
                                                                   const ImageInfo& info);
  ~FlyRenderer();

  /// Applies the frame's uploads (acknowledged to `streamer`) and draws `view`, timing the
  /// GPU's work with a timer query read back a few frames later (never waited for). Returns
  /// the render thread's time, ms.
  double frame(uint64_t index, const View& view, const FrameUpdate& update, TileStreamer& streamer);
  /// GPU time per frame, ms; -1 where the driver gave none. Waits for queries still running.
  std::vector<double> finishGpuTimes();

  Renderer& renderer() { return *renderer_; }
  std::string description() const { return context_->description(); }

 private:
  FlyRenderer() = default;
  void collect(bool wait);

  std::unique_ptr<GlContext> context_;
  std::unique_ptr<Renderer> renderer_;
  struct Query {
    uint32_t id = 0;
    uint64_t frame = 0;
    bool running = false;
    std::chrono::steady_clock::time_point began;
  };
  std::vector<Query> queries_;
  size_t next_query_ = 0;
  std::vector<double> gpu_ms_;
};

/// The picture with each pixel tinted by the level that draws it (Backes et al., Fig. 1), as
/// tessera::levelsShown finds it for the resident tiles.
[[nodiscard]] Result<Picture> levelOverlay(const Picture& picture, const Archive& archive,
                                           const View& view,
                                           const std::function<bool(const TileId&)>& resident);

/// One frame of the flight for the report's plots.
struct ReportFrame {
  double t_ms = 0;
  double update_ms = 0;
  double render_ms = -1;  ///< render thread, apply and draw
  double gpu_ms = -1;
  double coverage = 0;
  bool fully_covered = false;
  uint64_t bytes_read = 0;
  double link_bytes_per_s = 0;  ///< the loader's throughput estimate
  uint32_t desired_level = 0;
  uint32_t requested_level = 0;  ///< finest level requested (adaptive scheduling)
  uint32_t finest_full_level = 0;
};

/// A picture for the report, PNG bytes embedded as a data URI.
struct ReportPicture {
  std::string caption;
  std::vector<uint8_t> png;
};

/// Writes a self-contained HTML page (inline SVG plots and pictures, no scripts, nothing
/// fetched): the summary, frame time per frame (as Backes et al., Fig. 5), coverage and bytes
/// read over time, and the pictures. Fails naming the path.
[[nodiscard]] Result<void> writeFlyReport(const std::string& path, const nlohmann::json& summary,
                                          const std::vector<ReportFrame>& frames,
                                          const std::vector<ReportPicture>& pictures);

}  // namespace tessera::cli
