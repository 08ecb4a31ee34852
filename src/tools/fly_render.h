#pragma once
// `tessera fly --render`: the flight drawn headless by a GPU renderer (EGL, llvmpipe without a
// GPU), with the render thread's and the GPU's time per frame, pictures at rest compared
// against the CPU reference, and the self-contained HTML report.

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <epoxy/gl.h>
#include <nlohmann/json.hpp>

#include <tessera/gl.h>
#include <tessera/render.h>
#include <tessera/stream.h>

namespace tessera::cli {

/// A headless context and renderer driven once per flight frame. Owned by one thread: the
/// flight's render thread.
class FlyRenderer {
 public:
  /// Makes the context and the renderer, and does before the flight's clock starts what its
  /// first frame would otherwise pay for: texture storage for every tile the streamer may keep
  /// resident at `first_view`'s viewport (residentTilesBound with `residency`), the staging
  /// ring, the colour target, and a first draw of `first_view`, waited for.
  [[nodiscard]] static Result<std::unique_ptr<FlyRenderer>> create(
      RendererKind kind, const ImageInfo& info, const View& first_view,
      const ResidencyOptions& residency, bool transcode_to_bc1 = false);
  ~FlyRenderer();

  /// Applies the frame's uploads (acknowledged to `streamer`; with `upload` false they are all
  /// declined, offered again later, and no texture is touched) and draws `view`, timing the
  /// GPU's work with a timer query read back a few frames later. Nothing here waits for the
  /// GPU: when every query is still running the frame goes untimed. Ends the frame with a
  /// fence (busy()). Returns the render thread's time, ms.
  double frame(uint64_t index, const View& view, const FrameUpdate& update, TileStreamer& streamer,
               bool upload = true);
  /// True while the GPU has not finished the last frame (its fence, polled: never waits). A
  /// real-time flight skips the frames that come while it is busy, as a display would drop
  /// them: queuing more work than the GPU does only makes every later frame later.
  bool busy();
  /// GPU time per frame, ms; -1 where the driver gave none or the frame went untimed. Waits
  /// for queries still running (after the flight).
  std::vector<double> finishGpuTimes();

  Renderer& renderer() { return *renderer_; }
  /// Milliseconds create() spent on the renderer before the flight (allocation, first draw).
  double setupMs() const { return setup_ms_; }
  /// Storage the renderer allocated after create() (RenderStats::storage_allocations): 0 when
  /// no frame of the flight allocated.
  uint32_t flightAllocations() const {
    return renderer_->stats().storage_allocations - allocations_at_start_;
  }
  const Renderer& renderer() const { return *renderer_; }
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
  GLsync frame_fence_ = nullptr;  ///< the last frame's end; null once seen signalled
  double setup_ms_ = 0;
  uint32_t allocations_at_start_ = 0;  ///< RenderStats::storage_allocations after create()
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
  bool levels = false;  ///< tinted by level (levelOverlay): shown beside the one before it
};

/// Writes `picture` to `file` as a PNG and, when `pictures` is not null, keeps its bytes
/// there under `caption` for the report. Fails naming the file.
[[nodiscard]] Result<void> writeReportPicture(const Picture& picture, const std::string& file,
                                              const std::string& caption,
                                              std::vector<ReportPicture>* pictures);

/// PSNR of identical pictures (infinite) as summary.json, the report and the demo state it.
inline constexpr double kIdenticalPsnrDb = 99;
/// The share of frames at full detail a flight should reach (issue 31's target).
inline constexpr double kFullDetailTargetPct = 95;

/// "56.3 dB", or "99.0 dB (identical)".
std::string formatPsnr(double psnr_db);
/// `text` safe inside HTML text and quoted attributes.
std::string htmlEscape(const std::string& text);
/// True when summary.json's `gl` names a renderer that draws on the CPU (llvmpipe, ...).
bool softwareRenderer(const nlohmann::json& summary);

/// One headline figure of a flight against its target (docs/demo.md, "What good looks
/// like"): the report, the demo page and the demo's printed lines all show these, so the
/// numbers are the same everywhere.
struct HeadlineFigure {
  std::string pointer;  ///< where summary.json holds it (a JSON pointer: "/update_ms/p99")
  std::string label;
  std::string short_label;  ///< for one-line summaries
  double value = 0;         ///< summary.json's number there
  std::string text;         ///< as shown: "81.3 %", "0.44 ms"
  std::string target;       ///< "≥ 95 %"
  enum class Verdict { kPass, kFail, kNotJudged } verdict = Verdict::kNotJudged;
  std::string note;  ///< why it is not judged (a figure a GPU sets, on a software renderer)
};
/// The headline figures of `summary` (summary.json), those it holds, in a fixed order.
std::vector<HeadlineFigure> headlineFigures(const nlohmann::json& summary);
/// A sentence on how much slower than real time the flight ran and why, or "" when it kept
/// up (within 5 %).
std::string slowdownNote(const nlohmann::json& summary);
/// The figures as an HTML table (figure, measured, target, pass/fail) with the notes; each
/// value cell carries data-figure (the pointer) and data-value (summary.json's number).
std::string figureTableHtml(const std::vector<HeadlineFigure>& figures);
/// The colours of levels 0 to level_count - 1 as levelOverlay tints them, in HTML.
std::string levelLegendHtml(uint32_t level_count);
/// The style sheet of the report and the demo page.
const char* reportCss();

/// Writes a self-contained HTML page (inline SVG plots and pictures, no scripts, nothing
/// fetched): what flew, the headline figures against their targets, a note when the flight
/// ran slower than real time, the failures, the jumps, frame time per frame (as Backes et al.,
/// Fig. 5), coverage, bytes read, the link and the levels over time, and the pictures with
/// the level legend. Fails naming the path.
[[nodiscard]] Result<void> writeFlyReport(const std::string& path, const nlohmann::json& summary,
                                          const std::vector<ReportFrame>& frames,
                                          const std::vector<ReportPicture>& pictures);

}  // namespace tessera::cli
