#include "fly_render.h"

#include <epoxy/gl.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iterator>

#include <fmt/format.h>

#include <tessera/picture_file.h>

#include "output/output_file.h"
#include "view_overlay.h"

namespace tessera::cli {

namespace {

/// Timer queries in flight: a frame's result is read this many frames later, by when a
/// pipelined driver has finished it.
constexpr size_t kQueryRing = 8;

}  // namespace

Result<std::unique_ptr<FlyRenderer>> FlyRenderer::create(RendererKind kind, const ImageInfo& info,
                                                         const View& first_view,
                                                         const ResidencyOptions& residency,
                                                         bool transcode_to_bc1) {
  std::unique_ptr<FlyRenderer> fly(new FlyRenderer());
  Result<std::unique_ptr<GlContext>> context = GlContext::createHeadless();
  if (!context) return forwardError(context);
  fly->context_ = std::move(*context);
  const auto started = std::chrono::steady_clock::now();
  // Sized for the whole flight now: on llvmpipe allocating (and clearing) the tile storage,
  // the staging ring and the target took 0.2-1.3 s of the first frame's time.
  // The tile array holds at most the driver's layer limit (tile quads decline past it).
  GLint max_layers = 0;
  glGetIntegerv(GL_MAX_ARRAY_TEXTURE_LAYERS, &max_layers);
  RendererOptions options;
  options.initial_layers = uint32_t(std::min<uint64_t>(
      residentTilesBound(info, first_view.viewportWidth(), first_view.viewportHeight(), residency),
      uint64_t(std::max(max_layers, 1))));
  options.initial_clip_tiles =
      clipRegionTiles(first_view.viewportWidth(), first_view.viewportHeight(), info.tile_size_px);
  options.transcode_to_bc1 = transcode_to_bc1;
  Result<std::unique_ptr<Renderer>> renderer = createRenderer(kind, info, options);
  if (!renderer) return forwardError(renderer);
  fly->renderer_ = std::move(*renderer);
  fly->queries_.resize(kQueryRing);
  for (Query& query : fly->queries_) glGenQueries(1, &query.id);
  // A first draw, with nothing resident yet, makes the colour target; waiting for it puts
  // the driver's own first-use work (threads, pages) before the flight's clock too.
  fly->renderer_->draw(first_view);
  glFinish();
  fly->setup_ms_ =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - started).count();
  fly->allocations_at_start_ = fly->renderer_->stats().storage_allocations;
  return fly;
}

FlyRenderer::~FlyRenderer() {
  if (!context_) return;
  context_->makeCurrent();
  for (Query& query : queries_) glDeleteQueries(1, &query.id);
  if (frame_fence_) glDeleteSync(frame_fence_);
  renderer_.reset();
}

double FlyRenderer::frame(uint64_t index, const View& view, const FrameUpdate& update,
                          TileStreamer& streamer, bool upload) {
  const auto started = std::chrono::steady_clock::now();
  collect(false);
  Query& query = queries_[next_query_];
  // Every query still running (a GPU some frames behind): this frame goes untimed rather than
  // wait for the oldest, which once cost the render thread up to 2 s on llvmpipe.
  const bool timed = !query.running;
  if (timed) {
    query.began = started;
    glBeginQuery(GL_TIME_ELAPSED, query.id);
  }
  if (upload) {
    streamer.acknowledge(renderer_->apply(update));
  } else {
    ApplyResult declined;
    for (const auto& tile : update.uploads) declined.declined.push_back(tile->id);
    streamer.acknowledge(declined);
  }
  renderer_->draw(view);
  if (timed) {
    glEndQuery(GL_TIME_ELAPSED);
    query.frame = index;
    query.running = true;
    next_query_ = (next_query_ + 1) % queries_.size();
  }
  if (frame_fence_) glDeleteSync(frame_fence_);
  frame_fence_ = glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0);
  glFlush();
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - started)
      .count();
}

bool FlyRenderer::busy() {
  if (!frame_fence_) return false;
  const GLenum state = glClientWaitSync(frame_fence_, 0, 0);  // a poll: a timeout of 0
  if (state == GL_TIMEOUT_EXPIRED) return true;
  glDeleteSync(frame_fence_);
  frame_fence_ = nullptr;
  return false;
}

void FlyRenderer::collect(bool wait) {
  for (Query& query : queries_) {
    if (!query.running) continue;
    GLint available = 0;
    glGetQueryObjectiv(query.id, GL_QUERY_RESULT_AVAILABLE, &available);
    if (!available && !wait) continue;
    GLuint64 ns = 0;
    glGetQueryObjectui64v(query.id, GL_QUERY_RESULT, &ns);
    if (gpu_ms_.size() <= query.frame) gpu_ms_.resize(query.frame + 1, -1);
    // The GPU cannot have worked longer than the wall time since the query began; llvmpipe
    // reported hours for a process's first query. Such a result is dropped, not recorded.
    const double wall_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - query.began)
            .count();
    const double ms = double(ns) / 1e6;
    gpu_ms_[query.frame] = ms <= wall_ms ? ms : -1;
    query.running = false;
  }
}

std::vector<double> FlyRenderer::finishGpuTimes() {
  collect(true);
  return gpu_ms_;
}

Result<Picture> levelOverlay(const Picture& picture, const Archive& archive, const View& view,
                             const std::function<bool(const TileId&)>& resident) {
  ReferenceOptions options;
  options.available = resident;
  Result<std::vector<int32_t>> levels = levelsShown(archive, view, options);
  if (!levels) return forwardError(levels);
  Picture out = picture;
  for (size_t i = 0; i < levels->size() && i * 4 < out.rgba.size(); ++i) {
    if ((*levels)[i] < 0) continue;
    const LevelColour colour = levelColour(uint32_t((*levels)[i]));
    const float tint[3] = {colour.r, colour.g, colour.b};
    for (int c = 0; c < 3; ++c)
      out.rgba[i * 4 + c] = uint8_t(std::lround(out.rgba[i * 4 + c] * 0.5 + tint[c] * 127.5));
  }
  return out;
}

std::string formatPsnr(double psnr_db) {
  if (psnr_db >= kIdenticalPsnrDb) return fmt::format("{:.1f} dB (identical)", kIdenticalPsnrDb);
  return fmt::format("{:.1f} dB", psnr_db);
}

std::string htmlEscape(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '&': out += "&amp;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&#39;"; break;
      default: out += c;
    }
  }
  return out;
}

bool softwareRenderer(const nlohmann::json& summary) {
  const std::string gl = summary.value("gl", std::string());
  for (const char* name : {"llvmpipe", "softpipe", "SwiftShader", "lavapipe"})
    if (gl.find(name) != std::string::npos) return true;
  return false;
}

namespace {

/// The number at `pointer` in `summary`, or NaN when it is absent or null.
double numberAt(const nlohmann::json& summary, const std::string& pointer) {
  const nlohmann::json::json_pointer at(pointer);
  if (!summary.contains(at) || !summary[at].is_number()) return std::nan("");
  return summary[at].get<double>();
}

/// Milliseconds with the precision they deserve: 0.437 ms, 12.5 ms, 1544 ms.
std::string formatMs(double ms) {
  return ms < 10    ? fmt::format("{:.2f} ms", ms)
         : ms < 100 ? fmt::format("{:.1f} ms", ms)
                    : fmt::format("{:.0f} ms", ms);
}

}  // namespace

Result<void> writeReportPicture(const Picture& picture, const std::string& file,
                                const std::string& caption, std::vector<ReportPicture>* pictures) {
  TESSERA_TRY(writePng(picture, file));
  if (pictures) {
    std::ifstream in(file, std::ios::binary);
    pictures->push_back({caption, std::vector<uint8_t>(std::istreambuf_iterator<char>(in), {})});
  }
  return {};
}

std::vector<HeadlineFigure> headlineFigures(const nlohmann::json& summary) {
  const bool rendered = summary.contains("renderer");
  const bool software = softwareRenderer(summary);
  const double fps = summary.value("fps", 60.0);
  const double frame_ms = 1000 / fps;
  const std::string on_gpu =
      "not judged: " + summary.value("gl", std::string("a software renderer")) +
      " draws on the CPU, so frames take longer than on a GPU";
  std::vector<HeadlineFigure> figures;
  using Verdict = HeadlineFigure::Verdict;
  // Adds the figure at `pointer` when summary.json has it; `pass` judges it, `gpu_bound`
  // figures are not judged on a software renderer.
  auto add = [&](const std::string& pointer, const std::string& label,
                 const std::string& short_label, std::string text, const std::string& target,
                 bool pass, bool gpu_bound) {
    const double value = numberAt(summary, pointer);
    if (std::isnan(value)) return;
    HeadlineFigure figure{pointer,         label,  short_label,    value,
                          std::move(text), target, Verdict::kPass, ""};
    if (gpu_bound && software) {
      figure.verdict = Verdict::kNotJudged;
      figure.note = on_gpu;
    } else {
      figure.verdict = pass ? Verdict::kPass : Verdict::kFail;
    }
    figures.push_back(std::move(figure));
  };
  const double full = numberAt(summary, "/frames_full_detail_pct");
  add("/frames_full_detail_pct", "frames at full detail", "full detail",
      fmt::format("{:.1f} %", full), "≥ 95 %", full >= kFullDetailTargetPct, false);
  const double covered = numberAt(summary, "/frames_fully_covered_pct");
  add("/frames_fully_covered_pct", "frames with no hole (fully covered)", "no hole",
      fmt::format("{:.1f} %", covered), "100 %", covered >= 100, false);
  const double failures = numberAt(summary, "/load_failures");
  add("/load_failures", "failed loads", "failed loads", fmt::format("{:.0f}", failures), "0",
      failures == 0, false);
  // Scene flights (docs/fly.md, "Scenes"; issue 28's targets).
  const double untextured = numberAt(summary, "/untextured_frames");
  add("/untextured_frames", "frames with a visible object untextured", "untextured frames",
      fmt::format("{:.0f}", untextured), "0", untextured == 0, false);
  const double scene_psnr = numberAt(summary, "/scene_rest_psnr_db");
  add("/scene_rest_psnr_db", "picture at rest against every texture resident", "at rest",
      formatPsnr(scene_psnr), "≥ 40 dB", scene_psnr >= 40, false);
  const double texels = numberAt(summary, "/rest_texel_memory_pct");
  add("/rest_texel_memory_pct", "texel memory at rest, of every texture at full resolution",
      "texel memory", fmt::format("{:.1f} %", texels), "≤ 25 %", texels <= 25, false);
  const double median = numberAt(summary, "/full_detail_ms_median");
  add("/full_detail_ms_median", "time to full detail after a jump (median)", "to full detail",
      formatMs(median), "≤ 100 ms", median <= 100, rendered);
  const double psnr = numberAt(summary, "/rest_psnr_db_min");
  add("/rest_psnr_db_min", "picture at rest against the CPU reference (lowest)", "at rest",
      formatPsnr(psnr), "≥ 45 dB", psnr >= 45, false);
  const double update = numberAt(summary, "/update_ms/p99");
  add("/update_ms/p99", "streaming update on the render thread, p99", "streaming p99",
      formatMs(update), "≤ 1 ms", update <= 1, rendered);
  const double amplification = numberAt(summary, "/read_amplification");
  add("/read_amplification", "read amplification (bytes read / payload bytes)",
      "read amplification", fmt::format("{:.2f}", amplification), "≤ 1.3", amplification <= 1.3,
      false);
  const std::string a_frame = fmt::format("≤ {} (a frame)", formatMs(frame_ms));
  const double render = numberAt(summary, "/render_ms/p99");
  add("/render_ms/p99", "render thread p99 (apply + draw)", "render thread p99", formatMs(render),
      a_frame, render <= frame_ms, true);
  const double gpu = numberAt(summary, "/gpu_ms/p99");
  add("/gpu_ms/p99", "GPU time p99", "GPU p99", formatMs(gpu), a_frame, gpu <= frame_ms, true);
  const double slowdown = numberAt(summary, "/slowdown");
  add("/slowdown", "wall time over the path's time", "slowdown", fmt::format("{:.2f}x", slowdown),
      "≤ 1.05x", slowdown <= 1.05, rendered);
  return figures;
}

std::string slowdownNote(const nlohmann::json& summary) {
  const double slowdown = numberAt(summary, "/slowdown");
  if (std::isnan(slowdown) || slowdown <= 1.05) return "";
  return fmt::format(
      "This flight ran {:.1f} times slower than real time: its {:.1f}-s path took {:.1f} s, "
      "because {:.0f} % of its frames took longer than 1/{:g} s{}. Every frame of the path was "
      "drawn, so the camera moved more slowly than its nominal speed and the loaders had more "
      "time per frame; times are wall-clock times.",
      slowdown, numberAt(summary, "/path_s"), numberAt(summary, "/wall_s"),
      numberAt(summary, "/late_frames_pct"), summary.value("fps", 60.0),
      softwareRenderer(summary) ? " (" + summary.value("gl", std::string()) +
                                      " renders on the CPU cores the loaders use too)"
                                : "");
}

std::string figureTableHtml(const std::vector<HeadlineFigure>& figures) {
  std::string html =
      "<table class='figures'><tr><th>figure</th><th>measured</th><th>target</th><th></th></tr>";
  for (const HeadlineFigure& f : figures) {
    const char* verdict = f.verdict == HeadlineFigure::Verdict::kPass   ? "pass"
                          : f.verdict == HeadlineFigure::Verdict::kFail ? "fail"
                                                                        : "not-judged";
    const char* mark = f.verdict == HeadlineFigure::Verdict::kPass   ? "&#10003; pass"
                       : f.verdict == HeadlineFigure::Verdict::kFail ? "&#10007; fail"
                                                                     : "&ndash;";
    html += fmt::format(
        "<tr class='{0}'><td>{1}</td><td class='value' data-figure='{2}' data-value='{3}'>{4}"
        "</td><td>{5}</td><td class='verdict' title='{6}'>{7}</td></tr>",
        verdict, htmlEscape(f.label), htmlEscape(f.pointer), fmt::format("{}", f.value),
        htmlEscape(f.text), htmlEscape(f.target), htmlEscape(f.note), mark);
  }
  html += "</table>";
  std::string notes;
  for (const HeadlineFigure& f : figures)
    if (!f.note.empty() && notes.find(f.note) == std::string::npos)
      notes += "<p class='note'>&ndash; " + htmlEscape(f.note) + ".</p>";
  return html + notes;
}

std::string levelLegendHtml(uint32_t level_count) {
  std::string html = "<div class='level-legend'>Levels: ";
  for (uint32_t level = 0; level < level_count; ++level) {
    const LevelColour c = levelColour(level);
    html += fmt::format("<span class='swatch' style='background:rgb({},{},{})'></span>{}{} ",
                        int(c.r * 255), int(c.g * 255), int(c.b * 255), level,
                        level == 0                 ? " (full resolution)"
                        : level + 1 == level_count ? " (coarsest)"
                                                   : "");
  }
  return html + "</div>";
}

const char* reportCss() {
  return "body{font-family:sans-serif;margin:24px auto;max-width:960px;padding:0 12px;"
         "color:#222;line-height:1.4}h1{font-size:24px}h2{font-size:19px;margin-top:28px}"
         "table{border-collapse:collapse;margin:8px 0}td,th{border:1px solid #ccc;padding:3px "
         "8px;text-align:right;vertical-align:top}th{background:#f4f4f4}td:first-child,"
         "th:first-child{text-align:left}tr.pass .verdict{color:#16794c;font-weight:bold}"
         "tr.fail .verdict{color:#b3261e;font-weight:bold}tr.not-judged .verdict{color:#777}"
         ".verdict,.value,table.figures td:nth-child(3){white-space:nowrap}"
         ".card{display:flex;gap:16px;align-items:flex-start}.card>div{flex:1;min-width:0}"
         ".card>figure{flex:0 0 300px;margin:8px 0}"
         ".note{font-size:13px;color:#555;margin:4px 0}.warning{background:#fff4e5;border:1px "
         "solid #f0b429;padding:8px 12px;margin:12px 0}.failure{background:#fdecea;border:1px "
         "solid #b3261e;padding:8px 12px;margin:12px 0}img{max-width:100%;height:auto;display:"
         "block}figure{margin:8px 0}figcaption{font-size:13px;color:#444}.pair{display:grid;"
         "grid-template-columns:1fr 1fr;gap:12px}svg{max-width:100%;height:auto;display:block}"
         ".level-legend{font-size:13px;margin:4px 0 16px}.swatch{display:inline-block;width:12px;"
         "height:12px;margin:0 3px 0 6px;vertical-align:-1px;border:1px solid #888}"
         "dt{font-weight:bold}dd{margin:0 0 "
         "6px 16px}";
}

namespace {

std::string base64(const std::vector<uint8_t>& bytes) {
  static const char* kAlphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  for (size_t i = 0; i < bytes.size(); i += 3) {
    const uint32_t chunk = uint32_t(bytes[i]) << 16 |
                           (i + 1 < bytes.size() ? uint32_t(bytes[i + 1]) << 8 : 0) |
                           (i + 2 < bytes.size() ? uint32_t(bytes[i + 2]) : 0);
    out += kAlphabet[(chunk >> 18) & 63];
    out += kAlphabet[(chunk >> 12) & 63];
    out += i + 1 < bytes.size() ? kAlphabet[(chunk >> 6) & 63] : '=';
    out += i + 2 < bytes.size() ? kAlphabet[chunk & 63] : '=';
  }
  return out;
}

struct Series {
  std::string name;
  std::string colour;
  std::vector<std::pair<double, double>> points;
};

/// Axis ticks from 0: a step of 1, 2 or 5 times a power of ten giving at most `most` steps up
/// to at least `max` (whole numbers only when `integers`).
struct Ticks {
  double step = 1;
  int count = 1;     ///< steps; the axis ends at step * count
  int decimals = 0;  ///< digits after the point every tick needs
};
Ticks niceTicks(double max, int most, bool integers) {
  if (!(max > 0)) max = 1;
  const double rough = max / most;
  const double power = std::pow(10.0, std::floor(std::log10(rough)));
  Ticks ticks;
  for (double m : {1.0, 2.0, 5.0, 10.0}) {
    ticks.step = m * power;
    if (ticks.step >= rough) break;
  }
  if (integers) ticks.step = std::max(1.0, std::round(ticks.step));
  ticks.count = std::max(1, int(std::ceil(max / ticks.step - 1e-9)));
  ticks.decimals = std::max(0, -int(std::floor(std::log10(ticks.step) + 1e-9)));
  return ticks;
}

/// Width of `text` in px at 12-px sans-serif, generously: layout reserves this much.
double textWidth(const std::string& text) {
  return 7.2 * double(text.size());
}

/// A line plot as inline SVG that scales to the page: title, then the legend (wrapping), then
/// the plot with ticks at round values from zero. Earlier series are drawn wider underneath,
/// so a series that equals a later one (the desired level and the level requested) still
/// shows. Every text lies inside the viewBox.
std::string svgPlot(const std::string& title, const std::string& x_label,
                    const std::string& y_label, const std::vector<Series>& series,
                    double y_max_hint = 0, bool integer_y = false) {
  constexpr double kW = 900, kPlotH = 200, kRight = 16, kLegendRow = 18, kZeroLift = 5;
  double x_max = 1e-9, y_max = y_max_hint;
  for (const Series& s : series)
    for (const auto& [x, y] : s.points) {
      x_max = std::max(x_max, x);
      y_max = std::max(y_max, y);
    }
  const Ticks yt = niceTicks(y_max, 5, integer_y), xt = niceTicks(x_max, 8, false);
  auto label = [](double v, int decimals) { return fmt::format("{:.{}f}", v, decimals); };
  double widest = 0;
  for (int i = 0; i <= yt.count; ++i)
    widest = std::max(widest, textWidth(label(yt.step * i, yt.decimals)));
  const double left = 22 + widest + 8;  // the rotated axis label, the tick labels, a gap
  // Legend rows under the title, wrapped to the width.
  std::vector<std::pair<double, double>> legend_at;  // x, row
  double lx = left, row = 0;
  for (const Series& s : series) {
    const double w = 18 + textWidth(s.name) + 18;
    if (lx + w > kW - kRight && lx > left) {
      lx = left;
      ++row;
    }
    legend_at.emplace_back(lx, row);
    lx += w;
  }
  const double top = 28 + (row + 1) * kLegendRow + 10;
  const double height = top + kPlotH + 44;
  const double y_top = yt.step * yt.count, x_right = xt.step * xt.count;
  auto sx = [&](double x) { return left + x / x_right * (kW - left - kRight); };
  // Zero sits a few px above the axis, so that a series at zero is not hidden by it.
  auto sy = [&](double y) { return top + kPlotH - kZeroLift - y / y_top * (kPlotH - kZeroLift); };
  std::string svg = fmt::format(
      "<svg class='plot' xmlns='http://www.w3.org/2000/svg' viewBox='0 0 {0} {1}' width='{0}' "
      "height='{1}' font-family='sans-serif' font-size='12'><text class='title' x='{2}' y='18' "
      "font-weight='bold' font-size='13'>{3}</text>",
      kW, height, left, htmlEscape(title));
  for (size_t i = 0; i < series.size(); ++i) {
    const auto [x, r] = legend_at[i];
    const double y = 28 + r * kLegendRow + 12;
    svg += fmt::format(
        "<g class='legend'><rect x='{}' y='{}' width='14' height='4' fill='{}'/><text x='{}' "
        "y='{}'>{}</text></g>",
        x, y - 6, series[i].colour, x + 18, y, htmlEscape(series[i].name));
  }
  svg += fmt::format("<line x1='{0}' y1='{1}' x2='{2}' y2='{1}' stroke='#444'/>", left,
                     top + kPlotH, kW - kRight);
  for (int i = 0; i <= yt.count; ++i) {
    const double y = sy(yt.step * i);
    svg += fmt::format("<line x1='{0}' y1='{1}' x2='{2}' y2='{1}' stroke='#e4e4e4'/>", left, y,
                       kW - kRight);
    svg += fmt::format("<text x='{}' y='{}' text-anchor='end'>{}</text>", left - 6, y + 4,
                       label(yt.step * i, yt.decimals));
  }
  for (int i = 0; i <= xt.count; ++i) {
    const double x = sx(xt.step * i);
    svg += fmt::format("<line x1='{0}' y1='{1}' x2='{0}' y2='{2}' stroke='#444'/>", x, top + kPlotH,
                       top + kPlotH + 4);
    svg += fmt::format("<text x='{}' y='{}' text-anchor='{}'>{}</text>", x, top + kPlotH + 18,
                       i == xt.count ? "end"
                       : i == 0      ? "start"
                                     : "middle",
                       label(xt.step * i, xt.decimals));
  }
  svg += fmt::format("<line x1='{0}' y1='{1}' x2='{0}' y2='{2}' stroke='#444'/>", left, top,
                     top + kPlotH);
  svg += fmt::format("<text x='{}' y='{}' text-anchor='middle'>{}</text>", (left + kW - kRight) / 2,
                     height - 8, htmlEscape(x_label));
  svg += fmt::format(
      "<text x='14' y='{0}' transform='rotate(-90 14 {0})' text-anchor='middle'>{1}</text>",
      top + kPlotH / 2, htmlEscape(y_label));
  for (size_t i = 0; i < series.size(); ++i) {
    // Steps: a frame's value holds until the next frame's.
    std::string points;
    for (size_t k = 0; k < series[i].points.size(); ++k) {
      const auto [x, y] = series[i].points[k];
      if (k > 0) points += fmt::format("{:.1f},{:.1f} ", sx(x), sy(series[i].points[k - 1].second));
      points += fmt::format("{:.1f},{:.1f} ", sx(x), sy(y));
    }
    const double width = series.size() > 1
                             ? 1.5 + 4.5 * double(series.size() - 1 - i) / double(series.size() - 1)
                             : 1.5;
    svg += fmt::format(
        "<polyline class='series' fill='none' stroke='{}' stroke-width='{:.2f}' "
        "stroke-opacity='0.85' stroke-linejoin='round' points='{}'/>",
        series[i].colour, width, points);
  }
  return svg + "</svg>";
}

std::string cell(const nlohmann::json& value) {
  if (value.is_null()) return "&ndash;";
  if (value.is_number_float()) return fmt::format("{:.1f}", value.get<double>());
  if (value.is_string()) return htmlEscape(value.get<std::string>());
  return htmlEscape(value.dump());
}

/// The report's first section: what flew, the verdicts, the notes, a thumbnail.
std::string reportHeader(const nlohmann::json& summary,
                         const std::vector<ReportPicture>& pictures) {
  std::string html = fmt::format(
      "<h1>tessera fly: {} over {}</h1><p>Viewport {}, {} frames a second, {}; {} frames, "
      "{:.1f} s of path, {:.1f} s of wall time.</p>",
      htmlEscape(summary.value("path", std::string())),
      htmlEscape(summary.value("archive", std::string())),
      htmlEscape(summary.value("viewport", std::string())), summary.value("fps", 0.0),
      summary.contains("renderer")
          ? fmt::format("drawn by the {} renderer on {}",
                        htmlEscape(summary.value("renderer", std::string())),
                        htmlEscape(summary.value("gl", std::string())))
          : std::string("not drawn (every upload accepted at once)"),
      summary.value("frames", 0), summary.value("path_s", 0.0), summary.value("wall_s", 0.0));
  if (const std::string note = slowdownNote(summary); !note.empty())
    html += "<p class='warning'>" + htmlEscape(note) + "</p>";
  if (summary.value("load_failures", uint64_t(0)) > 0) {
    html += fmt::format(
        "<div class='failure'><p><b>{} loads of {} tiles failed</b> ({} loaded on a later "
        "try); the first:</p><ul>",
        summary.value("load_failures", uint64_t(0)), summary.value("failed_tiles", uint64_t(0)),
        summary.value("failed_tiles_loaded_later", uint64_t(0)));
    for (const auto& failure : summary.value("failures", nlohmann::json::array()))
      html += "<li>" + htmlEscape(failure.value("message", std::string())) + "</li>";
    html += "</ul></div>";
  }
  html += "<h2>At a glance</h2><div class='card'><div>" +
          figureTableHtml(headlineFigures(summary)) +
          "<p class='note'>Targets are those of docs/demo.md (&ldquo;What good looks "
          "like&rdquo;).</p></div>";
  if (!pictures.empty())
    html += fmt::format(
        "<figure><img src='data:image/png;base64,{}' alt='the flight'><figcaption>{}"
        "</figcaption></figure>",
        base64(pictures.front().png), htmlEscape(pictures.front().caption));
  return html + "</div>";
}

/// What the figures mean, for a reader new to them.
const char* kGlossary =
    "<h2>What the figures mean</h2><dl>"
    "<dt>Full detail</dt><dd>Every visible tile at the level the view needs is on screen. Below "
    "100 % the screen showed a coarser level somewhere for a while, which is how the runtime "
    "hides loading.</dd>"
    "<dt>No hole (fully covered)</dt><dd>Every visible texel is drawn from some level, counted "
    "from the first covered frame; anything below 100 % is a hole on screen.</dd>"
    "<dt>Streaming update</dt><dd>The render thread's own cost of streaming per frame "
    "(TileStreamer::update); everything slow happens on loader threads.</dd>"
    "<dt>Read amplification</dt><dd>Bytes read over the payload bytes of the tiles delivered: "
    "gaps read inside merged reads and tiles dropped as stale count against it.</dd>"
    "<dt>At rest</dt><dd>The picture before each jump (or at the end) against the CPU reference "
    "drawn from the same resident tiles: it measures the renderer, not the codec; 99 dB means "
    "identical.</dd></dl>";

/// The jumps table: the times to full detail and to the whole clip region, the pictures at
/// rest against the reference.
std::string jumpsHtml(const nlohmann::json& summary) {
  if (!summary.contains("jumps")) return "";
  std::string html =
      "<h2>Jumps</h2><p class='note'>The start counts as a jump. &ndash; : the view moved on "
      "before it got there.</p><table><tr><th>at, s</th><th>full detail after, ms</th><th>whole "
      "clip region after, ms</th><th>at rest against the reference</th><th>largest "
      "difference</th></tr>";
  for (const auto& jump : summary["jumps"]) {
    const nlohmann::json psnr = jump.value("rest_psnr_db", nlohmann::json());
    html += fmt::format("<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                        fmt::format("{:.2f}", jump.value("at_s", 0.0)),
                        cell(jump.value("full_detail_ms", nlohmann::json())),
                        cell(jump.value("clip_region_ms", nlohmann::json())),
                        psnr.is_number() ? formatPsnr(psnr.get<double>()) : std::string("&ndash;"),
                        cell(jump.value("rest_max_abs", nlohmann::json())));
  }
  return html + "</table>";
}

/// The pictures, each at rest beside its level-tinted twin, with the level legend.
std::string picturesHtml(const nlohmann::json& summary,
                         const std::vector<ReportPicture>& pictures) {
  if (pictures.empty()) return "";
  std::string html = "<h2>Pictures</h2>";
  for (size_t i = 0; i < pictures.size(); ++i) {
    const bool paired = i + 1 < pictures.size() && pictures[i + 1].levels && !pictures[i].levels;
    auto figure = [&](const ReportPicture& picture) {
      return fmt::format(
          "<figure><img src='data:image/png;base64,{}' alt='{}'><figcaption>{}</figcaption>"
          "</figure>",
          base64(picture.png), htmlEscape(picture.caption), htmlEscape(picture.caption));
    };
    if (paired) {
      html += "<div class='pair'>" + figure(pictures[i]) + figure(pictures[i + 1]) + "</div>";
      html += levelLegendHtml(summary.value("levels", 1u));
      ++i;
    } else {
      html += figure(pictures[i]);
      if (pictures[i].levels) html += levelLegendHtml(summary.value("levels", 1u));
    }
  }
  return html;
}

/// The plots: work per frame, coverage, bytes read, the link, the levels.
std::string plotsHtml(const std::vector<ReportFrame>& frames) {
  Series update{"streaming update (render thread)", "#1f77b4", {}};
  Series render{"apply + draw (render thread)", "#ff7f0e", {}};
  Series gpu{"GPU", "#2ca02c", {}};
  Series coverage{"share of the screen at the desired level", "#1f77b4", {}};
  Series covered{"no hole: 1, a hole: 0", "#d62728", {}};
  Series read{"MiB read since the start", "#9467bd", {}};
  Series throughput{"throughput the loader measures, MB/s", "#8c564b", {}};
  Series desired{"desired level", "#9a9a9a", {}};
  Series requested{"finest level requested", "#d62728", {}};
  Series finest{"finest level covering the view", "#2ca02c", {}};
  for (const ReportFrame& f : frames) {
    const double t = f.t_ms / 1000;
    update.points.emplace_back(t, f.update_ms);
    if (f.render_ms >= 0) render.points.emplace_back(t, f.render_ms);
    if (f.gpu_ms >= 0) gpu.points.emplace_back(t, f.gpu_ms);
    coverage.points.emplace_back(t, f.coverage);
    covered.points.emplace_back(t, f.fully_covered ? 1 : 0);
    read.points.emplace_back(t, double(f.bytes_read) / (1 << 20));
    throughput.points.emplace_back(t, f.link_bytes_per_s / 1e6);
    desired.points.emplace_back(t, f.desired_level);
    requested.points.emplace_back(t, f.requested_level);
    finest.points.emplace_back(t, f.finest_full_level);
  }
  std::vector<Series> times{update};
  if (!render.points.empty()) times.push_back(render);
  if (!gpu.points.empty()) times.push_back(gpu);
  const std::string x_label = "wall-clock time since the start, s";
  return "<h2>Work per frame (as Backes et al., Fig. 5)</h2>" +
         svgPlot("Render-thread and GPU time per frame", x_label, "ms", times) +
         "<h2>Coverage</h2>" +
         svgPlot("The screen at the level it needs", x_label, "fraction", {coverage, covered}, 1) +
         "<h2>Reading</h2>" + svgPlot("Bytes read from the archive", x_label, "MiB", {read}) +
         "<h2>Link and levels</h2>" +
         svgPlot("Throughput the loader measures", x_label, "MB/s", {throughput}) +
         svgPlot("Levels (0 = full resolution)", x_label, "level", {desired, requested, finest}, 1,
                 true);
}

}  // namespace

Result<void> writeFlyReport(const std::string& path, const nlohmann::json& summary,
                            const std::vector<ReportFrame>& frames,
                            const std::vector<ReportPicture>& pictures) {
  std::string html = fmt::format(
      "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><meta name='viewport' "
      "content='width=device-width'><title>tessera fly: {}</title><style>{}</style></head>"
      "<body>",
      htmlEscape(summary.value("path", std::string())), reportCss());
  html += reportHeader(summary, pictures);
  html += jumpsHtml(summary);
  html += plotsHtml(frames);
  html += picturesHtml(summary, pictures);
  html += kGlossary;
  html += "</body></html>\n";
  return detail::writeFileAtomically(path,
                                     {reinterpret_cast<const uint8_t*>(html.data()), html.size()});
}

}  // namespace tessera::cli
