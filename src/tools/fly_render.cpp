#include "fly_render.h"

#include <epoxy/gl.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include <fmt/format.h>

#include "output/output_file.h"
#include "view_overlay.h"

namespace tessera::cli {

namespace {

/// Timer queries in flight: a frame's result is read this many frames later, by when a
/// pipelined driver has finished it.
constexpr size_t kQueryRing = 8;

}  // namespace

Result<std::unique_ptr<FlyRenderer>> FlyRenderer::create(RendererKind kind, const ImageInfo& info) {
  std::unique_ptr<FlyRenderer> fly(new FlyRenderer());
  Result<std::unique_ptr<GlContext>> context = GlContext::createHeadless();
  if (!context) return forwardError(context);
  fly->context_ = std::move(*context);
  Result<std::unique_ptr<Renderer>> renderer = createRenderer(kind, info);
  if (!renderer) return forwardError(renderer);
  fly->renderer_ = std::move(*renderer);
  fly->queries_.resize(kQueryRing);
  for (Query& query : fly->queries_) glGenQueries(1, &query.id);
  return fly;
}

FlyRenderer::~FlyRenderer() {
  if (!context_) return;
  context_->makeCurrent();
  for (Query& query : queries_) glDeleteQueries(1, &query.id);
  renderer_.reset();
}

double FlyRenderer::frame(uint64_t index, const View& view, const FrameUpdate& update,
                          TileStreamer& streamer) {
  const auto started = std::chrono::steady_clock::now();
  Query& query = queries_[next_query_];
  if (query.running) collect(true);  // the ring is full: the oldest must be read first
  query.began = std::chrono::steady_clock::now();
  glBeginQuery(GL_TIME_ELAPSED, query.id);
  streamer.acknowledge(renderer_->apply(update));
  renderer_->draw(view);
  glEndQuery(GL_TIME_ELAPSED);
  glFlush();
  query.frame = index;
  query.running = true;
  next_query_ = (next_query_ + 1) % queries_.size();
  collect(false);
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - started)
      .count();
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

std::string escape(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '&': out += "&amp;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

struct Series {
  std::string name;
  std::string colour;
  std::vector<std::pair<double, double>> points;
};

/// A line plot as inline SVG, axes from zero, with a legend.
std::string svgPlot(const std::string& title, const std::string& x_label,
                    const std::string& y_label, const std::vector<Series>& series,
                    double y_max_hint = 0) {
  constexpr double kW = 860, kH = 260, kLeft = 60, kRight = 20, kTop = 30, kBottom = 40;
  double x_max = 1e-9, y_max = y_max_hint;
  for (const Series& s : series)
    for (const auto& [x, y] : s.points) {
      x_max = std::max(x_max, x);
      y_max = std::max(y_max, y);
    }
  if (y_max <= 0) y_max = 1;
  y_max *= 1.05;
  auto sx = [&](double x) { return kLeft + x / x_max * (kW - kLeft - kRight); };
  auto sy = [&](double y) { return kH - kBottom - y / y_max * (kH - kTop - kBottom); };
  std::string svg = fmt::format(
      "<svg xmlns='http://www.w3.org/2000/svg' width='{}' height='{}' font-family='sans-serif' "
      "font-size='12'><text x='{}' y='18' font-weight='bold'>{}</text>",
      kW, kH, kLeft, escape(title));
  svg += fmt::format("<line x1='{0}' y1='{1}' x2='{2}' y2='{1}' stroke='#444'/>", kLeft,
                     kH - kBottom, kW - kRight);
  svg += fmt::format("<line x1='{0}' y1='{1}' x2='{0}' y2='{2}' stroke='#444'/>", kLeft, kTop,
                     kH - kBottom);
  for (int i = 0; i <= 4; ++i) {
    const double y = y_max * i / 4, x = x_max * i / 4;
    svg +=
        fmt::format("<text x='{}' y='{}' text-anchor='end'>{:.3g}</text>", kLeft - 4, sy(y) + 4, y);
    svg += fmt::format("<line x1='{0}' y1='{1}' x2='{2}' y2='{1}' stroke='#ddd'/>", kLeft, sy(y),
                       kW - kRight);
    svg += fmt::format("<text x='{}' y='{}' text-anchor='middle'>{:.4g}</text>", sx(x),
                       kH - kBottom + 16, x);
  }
  svg += fmt::format("<text x='{}' y='{}' text-anchor='middle'>{}</text>", (kLeft + kW) / 2, kH - 6,
                     escape(x_label));
  svg += fmt::format(
      "<text x='14' y='{}' transform='rotate(-90 14 {})' text-anchor='middle'>{}"
      "</text>",
      (kTop + kH - kBottom) / 2, (kTop + kH - kBottom) / 2, escape(y_label));
  double legend_x = kLeft + 200;
  for (const Series& s : series) {
    std::string points;
    for (const auto& [x, y] : s.points) points += fmt::format("{:.1f},{:.1f} ", sx(x), sy(y));
    svg += fmt::format("<polyline fill='none' stroke='{}' stroke-width='1.2' points='{}'/>",
                       s.colour, points);
    svg += fmt::format(
        "<rect x='{}' y='10' width='12' height='4' fill='{}'/><text x='{}' "
        "y='16'>{}</text>",
        legend_x, s.colour, legend_x + 16, escape(s.name));
    legend_x += 40 + 7.0 * double(s.name.size());
  }
  return svg + "</svg>";
}

std::string cell(const nlohmann::json& value) {
  if (value.is_null()) return "-";
  if (value.is_number_float()) return fmt::format("{:.3g}", value.get<double>());
  if (value.is_string()) return escape(value.get<std::string>());
  return escape(value.dump());
}

}  // namespace

Result<void> writeFlyReport(const std::string& path, const nlohmann::json& summary,
                            const std::vector<ReportFrame>& frames,
                            const std::vector<ReportPicture>& pictures) {
  std::string html =
      "<!DOCTYPE html><html><head><meta charset='utf-8'><title>tessera fly report</title>"
      "<style>body{font-family:sans-serif;margin:24px;max-width:960px}table{border-collapse:"
      "collapse}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}th{background:#f4f4"
      "f4}td:first-child{text-align:left}figure{display:inline-block;margin:8px}figcaption{font-"
      "size:12px}</style></head><body>";
  html += fmt::format(
      "<h1>tessera fly</h1><p>{} &mdash; path {}, viewport {}, {} fps, renderer "
      "{} ({})</p>",
      cell(summary.value("archive", nlohmann::json())),
      cell(summary.value("path", nlohmann::json())),
      cell(summary.value("viewport", nlohmann::json())),
      cell(summary.value("fps", nlohmann::json())),
      cell(summary.value("renderer", nlohmann::json())),
      cell(summary.value("gl", nlohmann::json())));
  html += "<h2>Summary</h2><table>";
  for (const char* key :
       {"frames", "frames_full_detail_pct", "frames_fully_covered_pct", "startup_ms", "bytes_read",
        "read_amplification", "tiles_loaded", "load_failures", "peak_rss_bytes", "simulated_link",
        "adaptive", "reads_cancelled", "requests_cancelled", "link_bytes_per_s", "link_latency_ms"})
    if (summary.contains(key))
      html += fmt::format("<tr><td>{}</td><td>{}</td></tr>", key, cell(summary[key]));
  for (const char* key : {"update_ms", "render_ms", "gpu_ms"})
    if (summary.contains(key) && summary[key].is_object())
      html += fmt::format("<tr><td>{} p50 / p99 / max</td><td>{} / {} / {}</td></tr>", key,
                          cell(summary[key]["p50"]), cell(summary[key]["p99"]),
                          cell(summary[key]["max"]));
  html += "</table>";
  if (summary.contains("jumps")) {
    html +=
        "<h2>Jumps</h2><table><tr><th>at s</th><th>full detail ms</th><th>clip region "
        "ms</th><th>PSNR at rest dB</th><th>max difference</th></tr>";
    for (const auto& jump : summary["jumps"])
      html += fmt::format("<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                          cell(jump.value("at_s", nlohmann::json())),
                          cell(jump.value("full_detail_ms", nlohmann::json())),
                          cell(jump.value("clip_region_ms", nlohmann::json())),
                          cell(jump.value("rest_psnr_db", nlohmann::json())),
                          cell(jump.value("rest_max_abs", nlohmann::json())));
    html += "</table>";
  }
  Series update{"streaming update (render thread)", "#1f77b4", {}};
  Series render{"apply + draw (render thread)", "#ff7f0e", {}};
  Series gpu{"GPU", "#2ca02c", {}};
  Series coverage{"coverage at the desired level", "#1f77b4", {}};
  Series covered{"fully covered (1) or not (0)", "#d62728", {}};
  Series read{"bytes read, MiB", "#9467bd", {}};
  for (const ReportFrame& f : frames) {
    const double t = f.t_ms / 1000;
    update.points.emplace_back(t, f.update_ms);
    if (f.render_ms >= 0) render.points.emplace_back(t, f.render_ms);
    if (f.gpu_ms >= 0) gpu.points.emplace_back(t, f.gpu_ms);
    coverage.points.emplace_back(t, f.coverage);
    covered.points.emplace_back(t, f.fully_covered ? 1 : 0);
    read.points.emplace_back(t, double(f.bytes_read) / (1 << 20));
  }
  std::vector<Series> times{update};
  if (!render.points.empty()) times.push_back(render);
  if (!gpu.points.empty()) times.push_back(gpu);
  html += "<h2>Frame time (Backes et al., Fig. 5)</h2>" +
          svgPlot("Work per frame", "time, s", "ms", times);
  html += "<h2>Coverage</h2>" +
          svgPlot("Screen at the desired level", "time, s", "fraction", {coverage, covered}, 1);
  html += "<h2>Reading</h2>" + svgPlot("Bytes read since the start", "time, s", "MiB", {read});
  // The link as measured and what the scheduler asked for (Marvie & Bouatouch, part III).
  Series throughput{"throughput estimate, MB/s", "#8c564b", {}};
  Series desired{"desired level", "#7f7f7f", {}};
  Series requested{"finest level requested", "#d62728", {}};
  Series finest{"finest level covering the view", "#2ca02c", {}};
  for (const ReportFrame& f : frames) {
    const double t = f.t_ms / 1000;
    throughput.points.emplace_back(t, f.link_bytes_per_s / 1e6);
    desired.points.emplace_back(t, f.desired_level);
    requested.points.emplace_back(t, f.requested_level);
    finest.points.emplace_back(t, f.finest_full_level);
  }
  html += "<h2>Link and levels</h2>" +
          svgPlot("Throughput the loader measures", "time, s", "MB/s", {throughput}) +
          svgPlot("Levels (0 = full resolution)", "time, s", "level", {desired, requested, finest});
  if (!pictures.empty()) {
    html += "<h2>Pictures</h2>";
    for (const ReportPicture& picture : pictures)
      html += fmt::format(
          "<figure><img src='data:image/png;base64,{}'><figcaption>{}"
          "</figcaption></figure>",
          base64(picture.png), escape(picture.caption));
  }
  html += "</body></html>\n";
  return detail::writeFileAtomically(path,
                                     {reinterpret_cast<const uint8_t*>(html.data()), html.size()});
}

}  // namespace tessera::cli
