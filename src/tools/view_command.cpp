// `tessera view`: the interactive viewer. A GLFW window whose frame loop only polls the
// streamer (update, apply, draw: the render thread never waits on the loader), a Dear ImGui
// panel with the runtime's figures, overlays and screenshots (docs/view.md).
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <thread>
#include <unordered_set>

#include <epoxy/gl.h>
#include <GLFW/glfw3.h>
#include <imgui.h>
#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_opengl3.h>

#include <fmt/format.h>

#include <tessera/archive.h>
#include <tessera/open.h>
#include <tessera/picture_file.h>
#include <tessera/gl.h>
#include <tessera/renderer.h>
#include <tessera/link.h>
#include <tessera/stream.h>

#include "cli.h"
#include "display_window_option.h"
#include "gl/window.h"
#include "view_camera.h"
#include "scene_fly_command.h"
#include "scene_view_command.h"
#include "view_command.h"
#include "view_overlay.h"
#include "view_panel.h"
#include "view_screenshot.h"

namespace tessera::cli {

namespace {

using Clock = std::chrono::steady_clock;

constexpr double kFlyPitchRad = -0.6;
constexpr size_t kFrameHistory = 300;

// What the window's callbacks change and the frame loop reads. Render thread only (GLFW calls
// back from glfwPollEvents, on the thread that polls).
struct Viewer {
  GLFWwindow* window = nullptr;
  ImageInfo info;
  View view;
  DisplayWindow display;          ///< the window/level drawn with (keys change it)
  DisplayWindow initial_display;  ///< what 0 returns to
  OverlayOptions overlays;
  bool show_panel = true;
  bool screenshot_requested = false;
  /// The panel's box at the last frame, px (x, y, width, height): --frames reports it.
  struct {
    float x = 0, y = 0, width = 0, height = 0;
  } panel_box;
  bool dragging = false;
  double last_cursor_x = 0, last_cursor_y = 0;  ///< framebuffer pixels
  // Windowed placement, restored when fullscreen ends.
  int windowed_x = 0, windowed_y = 0, windowed_w = 0, windowed_h = 0;
};

Viewer& viewerOf(GLFWwindow* window) {
  return *static_cast<Viewer*>(glfwGetWindowUserPointer(window));
}

// Cursor positions come in window coordinates; the view is in framebuffer pixels (they differ
// on HiDPI screens).
void cursorInFramebuffer(GLFWwindow* window, double& x, double& y) {
  int ww = 0, wh = 0, fw = 0, fh = 0;
  glfwGetWindowSize(window, &ww, &wh);
  glfwGetFramebufferSize(window, &fw, &fh);
  glfwGetCursorPos(window, &x, &y);
  if (ww > 0 && wh > 0) {
    x *= double(fw) / ww;
    y *= double(fh) / wh;
  }
}

void fitView(Viewer& v) {
  v.view.ortho = fitImage(v.info, v.view.viewportWidth(), v.view.viewportHeight());
  if (v.view.kind == View::Kind::kPerspective)
    v.view.perspective = perspectiveFrom(v.view.ortho, v.info, kFlyPitchRad);
}

void togglePerspective(Viewer& v) {
  if (v.view.kind == View::Kind::kOrtho) {
    v.view.perspective = perspectiveFrom(v.view.ortho, v.info, kFlyPitchRad);
    v.view.kind = View::Kind::kPerspective;
  } else {
    v.view.ortho = orthoFrom(v.view.perspective, v.info);
    v.view.kind = View::Kind::kOrtho;
  }
}

void toggleFullscreen(Viewer& v) {
  if (glfwGetWindowMonitor(v.window)) {
    glfwSetWindowMonitor(v.window, nullptr, v.windowed_x, v.windowed_y, v.windowed_w, v.windowed_h,
                         0);
    return;
  }
  GLFWmonitor* monitor = glfwGetPrimaryMonitor();
  const GLFWvidmode* mode = monitor ? glfwGetVideoMode(monitor) : nullptr;
  if (!mode) return;
  glfwGetWindowPos(v.window, &v.windowed_x, &v.windowed_y);
  glfwGetWindowSize(v.window, &v.windowed_w, &v.windowed_h);
  glfwSetWindowMonitor(v.window, monitor, 0, 0, mode->width, mode->height, mode->refreshRate);
}

// Wheel and +/-: one step zooms by this factor, about 7 steps per doubling.
constexpr double kZoomStep = 0.9;

void onScroll(GLFWwindow* window, double, double y_offset) {
  if (ImGui::GetIO().WantCaptureMouse) return;
  Viewer& v = viewerOf(window);
  const double factor = std::pow(kZoomStep, y_offset);
  if (v.view.kind == View::Kind::kPerspective) {
    flyClimb(v.view.perspective, v.info, factor);
    return;
  }
  double x = 0, y = 0;
  cursorInFramebuffer(window, x, y);
  zoomAround(v.view.ortho, v.info, factor, x, y);
  clampToImage(v.view.ortho, v.info);
}

void onMouseButton(GLFWwindow* window, int button, int action, int) {
  Viewer& v = viewerOf(window);
  if (button != GLFW_MOUSE_BUTTON_LEFT) return;
  if (action == GLFW_PRESS && !ImGui::GetIO().WantCaptureMouse) {
    v.dragging = true;
    cursorInFramebuffer(window, v.last_cursor_x, v.last_cursor_y);
  } else if (action == GLFW_RELEASE) {
    v.dragging = false;
  }
}

void onCursor(GLFWwindow* window, double, double) {
  Viewer& v = viewerOf(window);
  if (!v.dragging) return;
  double x = 0, y = 0;
  cursorInFramebuffer(window, x, y);
  const double dx = x - v.last_cursor_x, dy = y - v.last_cursor_y;
  v.last_cursor_x = x;
  v.last_cursor_y = y;
  if (v.view.kind == View::Kind::kPerspective) {
    flyTurn(v.view.perspective, dx, dy);
  } else {
    panByScreen(v.view.ortho, dx, dy);
    clampToImage(v.view.ortho, v.info);
  }
}

// The window/level keys: [ ] move the window down and up by a tenth of its width, , . narrow
// and widen it by a fifth, ; ' lower and raise the gamma by 10 %, 0 returns to the start.
void adjustDisplayWindow(Viewer& v, int key) {
  DisplayWindow& w = v.display;
  const double width = w.high - w.low, centre = (w.high + w.low) / 2;
  double new_width = width, new_centre = centre;
  switch (key) {
    case GLFW_KEY_LEFT_BRACKET: new_centre -= width / 10; break;
    case GLFW_KEY_RIGHT_BRACKET: new_centre += width / 10; break;
    case GLFW_KEY_COMMA: new_width /= 1.2; break;
    case GLFW_KEY_PERIOD: new_width *= 1.2; break;
    case GLFW_KEY_SEMICOLON: w.gamma /= 1.1; break;
    case GLFW_KEY_APOSTROPHE: w.gamma *= 1.1; break;
    default: w = v.initial_display; return;
  }
  w.low = new_centre - new_width / 2;
  w.high = new_centre + new_width / 2;
}

void onKey(GLFWwindow* window, int key, int, int action, int mods) {
  if (action != GLFW_PRESS || ImGui::GetIO().WantCaptureKeyboard) return;
  Viewer& v = viewerOf(window);
  switch (key) {
    case GLFW_KEY_Q:
    case GLFW_KEY_ESCAPE: glfwSetWindowShouldClose(window, GLFW_TRUE); break;
    case GLFW_KEY_HOME: fitView(v); break;
    case GLFW_KEY_F11:
    case GLFW_KEY_F: toggleFullscreen(v); break;
    case GLFW_KEY_P: togglePerspective(v); break;
    case GLFW_KEY_L: v.overlays.levels = !v.overlays.levels; break;
    case GLFW_KEY_C: v.overlays.clip_regions = !v.overlays.clip_regions; break;
    case GLFW_KEY_G: v.overlays.grid = !v.overlays.grid; break;
    case GLFW_KEY_F1: v.show_panel = !v.show_panel; break;
    case GLFW_KEY_F12: v.screenshot_requested = true; break;
    case GLFW_KEY_LEFT_BRACKET:
    case GLFW_KEY_RIGHT_BRACKET:
    case GLFW_KEY_COMMA:
    case GLFW_KEY_PERIOD:
    case GLFW_KEY_SEMICOLON:
    case GLFW_KEY_APOSTROPHE:
    case GLFW_KEY_0: adjustDisplayWindow(v, key); break;
    // Plain S pans down (WASD); Ctrl+S is the screenshot.
    case GLFW_KEY_S:
      if (mods & GLFW_MOD_CONTROL) v.screenshot_requested = true;
      break;
    default: break;
  }
}

// Held keys move the camera by time, not by frame, so the speed does not depend on the frame
// rate.
void applyHeldKeys(Viewer& v, double dt_s) {
  if (ImGui::GetIO().WantCaptureKeyboard) return;
  auto held = [&](std::initializer_list<int> keys) {
    for (int key : keys)
      if (glfwGetKey(v.window, key) == GLFW_PRESS) return 1.0;
    return 0.0;
  };
  if (glfwGetKey(v.window, GLFW_KEY_LEFT_CONTROL) == GLFW_PRESS ||
      glfwGetKey(v.window, GLFW_KEY_RIGHT_CONTROL) == GLFW_PRESS)
    return;  // Ctrl+S is a screenshot, not a move
  const double right = held({GLFW_KEY_RIGHT, GLFW_KEY_D}) - held({GLFW_KEY_LEFT, GLFW_KEY_A});
  const double down = held({GLFW_KEY_DOWN, GLFW_KEY_S}) - held({GLFW_KEY_UP, GLFW_KEY_W});
  const double zoom_in =
      held({GLFW_KEY_EQUAL, GLFW_KEY_KP_ADD}) - held({GLFW_KEY_MINUS, GLFW_KEY_KP_SUBTRACT});
  if (v.view.kind == View::Kind::kPerspective) {
    // One altitude per second forward; +/- climb and sink by a factor of 4 per second.
    flyMove(v.view.perspective, v.info, -down * dt_s, right * dt_s);
    if (zoom_in != 0) flyClimb(v.view.perspective, v.info, std::pow(4.0, -zoom_in * dt_s));
    return;
  }
  // Half a screen per second, and a doubling of the zoom per half second.
  const double pan_px = 0.5 * std::max(v.view.ortho.viewport_w, v.view.ortho.viewport_h) * dt_s;
  if (right != 0 || down != 0) panByScreen(v.view.ortho, -right * pan_px, -down * pan_px);
  if (zoom_in != 0)
    zoomAround(v.view.ortho, v.info, std::pow(4.0, -zoom_in * dt_s), v.view.ortho.viewport_w / 2.0,
               v.view.ortho.viewport_h / 2.0);
  clampToImage(v.view.ortho, v.info);
}

// Dear ImGui's context and backends for one window; shut down before the GL context goes.
class ImGuiSession {
 public:
  explicit ImGuiSession(GLFWwindow* window) {
    IMGUI_CHECKVERSION();
    ImGui::CreateContext();
    ImGui::GetIO().IniFilename = nullptr;  // never leave an imgui.ini in the user's folder
    ImGui::StyleColorsDark();
    // Installs its callbacks over ours and chains to them.
    ImGui_ImplGlfw_InitForOpenGL(window, true);
    ImGui_ImplOpenGL3_Init("#version 450 core");
  }
  ~ImGuiSession() {
    ImGui_ImplOpenGL3_Shutdown();
    ImGui_ImplGlfw_Shutdown();
    ImGui::DestroyContext();
  }
  ImGuiSession(const ImGuiSession&) = delete;
  ImGuiSession& operator=(const ImGuiSession&) = delete;
};

// Bytes per second read by the loader, over windows of half a second.
class ReadRate {
 public:
  void add(Clock::time_point now, uint64_t bytes_total) {
    if (start_ == Clock::time_point{}) {
      start_ = now;
      start_bytes_ = bytes_total;
      return;
    }
    const double elapsed_s = std::chrono::duration<double>(now - start_).count();
    if (elapsed_s < 0.5) return;
    bytes_per_s_ = double(bytes_total - start_bytes_) / elapsed_s;
    start_ = now;
    start_bytes_ = bytes_total;
  }
  double bytesPerS() const { return bytes_per_s_; }

 private:
  Clock::time_point start_{};
  uint64_t start_bytes_ = 0;
  double bytes_per_s_ = 0;
};

struct FrameFigures {
  std::array<float, kFrameHistory> frame_ms{};   ///< ring buffer, oldest at `next`
  std::array<float, kFrameHistory> link_mb_s{};  ///< throughput estimate, same ring
  size_t next = 0;
  size_t count = 0;
  double streaming_ms = 0;  ///< render-thread time of update + apply, this frame
  ReadRate read_rate;
  void push(double ms, double link_bytes_per_s) {
    frame_ms[next] = float(ms);
    link_mb_s[next] = float(link_bytes_per_s / 1e6);
    next = (next + 1) % kFrameHistory;
    count = std::min(count + 1, kFrameHistory);
  }
  double meanMs() const {
    double sum = 0;
    for (size_t i = 0; i < count; ++i)
      sum += frame_ms[(next + kFrameHistory - 1 - i) % kFrameHistory];
    return count ? sum / count : 0;
  }
};

// The panel's sections, each under a collapsing header.

// The renderer's figures, and a choice of renderer; returns the one picked.
RendererKind panelRenderer(const Renderer& renderer) {
  int kind = renderer.kind() == RendererKind::kTileQuads ? 0 : 1;
  ImGui::RadioButton("tile quads", &kind, 0);
  ImGui::SameLine();
  ImGui::RadioButton("clipmap", &kind, 1);
  const RenderStats& rs = renderer.stats();
  ImGui::Text("resident %u tiles, %s on the GPU", rs.resident_tiles,
              formatBytes(rs.gpu_bytes).c_str());
  ImGui::Text("drawn %u, uploaded %u (%s), declined %u", rs.tiles_drawn, rs.uploads,
              formatBytes(rs.upload_bytes).c_str(), rs.declined);
  ImGui::Text("apply %.3f ms, draw %.3f ms", rs.apply_cpu_ms, rs.draw_cpu_ms);
  return kind == 0 ? RendererKind::kTileQuads : RendererKind::kClipmap;
}

void panelView(Viewer& v) {
  bool perspective = v.view.kind == View::Kind::kPerspective;
  if (ImGui::Checkbox("perspective fly-over (P)", &perspective)) togglePerspective(v);
  if (v.view.kind == View::Kind::kOrtho) {
    ImGui::Text("centre (%.0f, %.0f), %.4g texels/pixel", v.view.ortho.centre_x,
                v.view.ortho.centre_y, v.view.ortho.texels_per_pixel);
  } else {
    const PerspectiveView& p = v.view.perspective;
    ImGui::Text("eye (%.0f, %.0f) at %.0f, yaw %.0f, pitch %.0f deg", p.eye_x, p.eye_y, p.eye_z,
                p.yaw_rad * 57.2958, p.pitch_rad * 57.2958);
  }
  ImGui::Text("viewport %ux%u", v.view.viewportWidth(), v.view.viewportHeight());
}

void panelStreaming(const FrameReport& r, const FrameFigures& figures) {
  ImGui::Text("desired level %u, finest full level %u", r.desired_level, r.finest_full_level);
  ImGui::Text("coverage at the desired level %.1f%%%s", r.coverage_desired * 100,
              r.fully_covered ? "" : " (not fully covered)");
  ImGui::Text("loader queue %zu, in flight %zu", r.queue_length, r.in_flight);
  ImGui::Text("read %s/s, %s in all", formatBytes(uint64_t(figures.read_rate.bytesPerS())).c_str(),
              formatBytes(r.bytes_read_total).c_str());
  ImGui::Text("tiles loaded %llu, failures %llu", (unsigned long long)r.tiles_loaded_total,
              (unsigned long long)r.load_failures_total);
  ImGui::Text("uploads this frame %zu (%s), update %.3f ms", r.uploads,
              formatBytes(r.upload_bytes).c_str(), r.update_ms);
}

// The link as the loader measures it and what adaptive scheduling made of it (Marvie &
// Bouatouch, part III).
void panelLink(const FrameReport& r, const FrameFigures& figures) {
  ImGui::Text("throughput %s/s, latency %.1f ms, queue wait %.1f ms",
              formatBytes(uint64_t(r.link_bytes_per_s)).c_str(), r.link_latency_ms,
              r.queue_wait_ms);
  const PlotWindow link =
      plotWindow(figures.link_mb_s.data(), kFrameHistory, figures.next, figures.count, 0.1f);
  const std::string link_label = fmt::format("MB/s, max {:.2f}", link.largest);
  ImGui::PlotLines("##link", figures.link_mb_s.data(), link.count, link.offset, link_label.c_str(),
                   0.0f, link.max, ImVec2(ImGui::GetContentRegionAvail().x, 40));
  if (r.adaptive) {
    ImGui::Text("adaptive: %s budgets, levels down to %u (desired %u)",
                r.view_still ? "still" : "moving", r.requested_level, r.desired_level);
    ImGui::Text("per level %s, on the way %s, deferred %llu tiles",
                r.budget_bytes == UINT64_MAX ? "no limit" : formatBytes(r.budget_bytes).c_str(),
                formatBytes(r.requested_bytes).c_str(), (unsigned long long)r.deferred_tiles);
    ImGui::Text("memory %s of %s", formatBytes(r.memory_bytes).c_str(),
                formatBytes(r.memory_budget_bytes).c_str());
  } else {
    ImGui::TextDisabled("adaptive scheduling off (--adaptive on)");
  }
  ImGui::Text("cancelled: %llu queued requests, %llu reads in flight",
              (unsigned long long)r.cancelled_total, (unsigned long long)r.reads_cancelled_total);
  if (r.parents_queued_total || r.parent_fallbacks_total || r.children_read_early_total)
    ImGui::Text(
        "ptm parents: %llu queued for children, %llu read again for a decode, "
        "%llu children read during their load",
        (unsigned long long)r.parents_queued_total, (unsigned long long)r.parent_fallbacks_total,
        (unsigned long long)r.children_read_early_total);
}

void panelCache(const TileStreamer& streamer, size_t cache_budget_bytes) {
  const CacheStats c = streamer.cacheStats();
  const uint64_t lookups = c.hits + c.misses;
  ImGui::Text("hits %llu, misses %llu (%.1f%% hits)", (unsigned long long)c.hits,
              (unsigned long long)c.misses, lookups ? 100.0 * c.hits / lookups : 0.0);
  ImGui::Text("%s of %s, %zu tiles, %zu pinned", formatBytes(c.bytes).c_str(),
              formatBytes(cache_budget_bytes).c_str(), c.tiles, c.pinned);
  ImGui::Text("evictions %llu", (unsigned long long)c.evictions);
}

void panelOverlays(Viewer& v) {
  ImGui::Checkbox("levels in colour (L)", &v.overlays.levels);
  ImGui::Checkbox("clip regions and field of view (C)", &v.overlays.clip_regions);
  ImGui::Checkbox("tile grid (G)", &v.overlays.grid);
  for (uint32_t level = 0; level < v.info.level_count; ++level) {
    const LevelColour c = levelColour(level);
    if (level > 0) ImGui::SameLine();
    ImGui::TextColored(ImVec4(c.r, c.g, c.b, 1), "%u", level);
  }
}

// The panel; returns the renderer the user picked (the current one when unchanged).
RendererKind drawPanel(Viewer& v, const std::string& archive_name, const FrameUpdate& update,
                       const TileStreamer& streamer, const Renderer& renderer,
                       const FrameFigures& figures, size_t cache_budget_bytes,
                       const std::string& last_screenshot, int fw, int fh) {
  RendererKind picked = renderer.kind();
  // A fixed width (text wraps at it) and the height of the open sections, within the window;
  // the picture shows through a little.
  const PanelLayout layout = panelLayout(fw, fh);
  ImGui::SetNextWindowPos(ImVec2(layout.x, layout.y), ImGuiCond_FirstUseEver);
  ImGui::SetNextWindowSize(ImVec2(layout.width, 0), ImGuiCond_Always);
  ImGui::SetNextWindowSizeConstraints(ImVec2(0, 0), ImVec2(layout.width, layout.max_height));
  ImGui::SetNextWindowBgAlpha(0.8f);
  ImGui::Begin("tessera view");
  ImGui::PushTextWrapPos(0.0f);
  ImGui::Text("%s: %ux%u, %u levels, %u px tiles", archive_name.c_str(), v.info.width_px,
              v.info.height_px, v.info.level_count, v.info.tile_size_px);
  const double mean_ms = figures.meanMs();
  ImGui::Text("%.1f fps, %.2f ms/frame (mean of %zu); streaming %.3f ms",
              mean_ms > 0 ? 1000 / mean_ms : 0, mean_ms, figures.count, figures.streaming_ms);
  // Only the frames recorded so far, oldest first, on a scale that fits them.
  const PlotWindow frames =
      plotWindow(figures.frame_ms.data(), kFrameHistory, figures.next, figures.count, 20.0f);
  const std::string frames_label = fmt::format("frame ms, max {:.1f}", frames.largest);
  // An explicit width: ImGui 1.86 (Debian's) draws nothing for a negative one.
  ImGui::PlotLines("##frame_ms", figures.frame_ms.data(), frames.count, frames.offset,
                   frames_label.c_str(), 0.0f, frames.max,
                   ImVec2(ImGui::GetContentRegionAvail().x, 48));
  // One section at a time, under tabs: all of them open at once covered a quarter of the
  // picture.
  if (ImGui::BeginTabBar("sections", ImGuiTabBarFlags_FittingPolicyScroll)) {
    if (ImGui::BeginTabItem("Streaming")) {
      panelStreaming(update.report, figures);
      ImGui::EndTabItem();
    }
    if (ImGui::BeginTabItem("Renderer")) {
      picked = panelRenderer(renderer);
      ImGui::EndTabItem();
    }
    if (ImGui::BeginTabItem("View")) {
      panelView(v);
      ImGui::EndTabItem();
    }
    if (ImGui::BeginTabItem("Link")) {
      panelLink(update.report, figures);
      ImGui::EndTabItem();
    }
    if (ImGui::BeginTabItem("Cache")) {
      panelCache(streamer, cache_budget_bytes);
      ImGui::EndTabItem();
    }
    if (ImGui::BeginTabItem("Overlays")) {
      panelOverlays(v);
      ImGui::EndTabItem();
    }
    if (ImGui::BeginTabItem("Keys")) {
      ImGui::TextDisabled(
          "drag: pan | wheel: zoom | arrows/WASD: pan | +/-: zoom | Home: fit | P: fly-over | "
          "fly-over: WASD move, drag look, wheel or +/- altitude | F/F11: fullscreen | F1: "
          "panel | L C G: overlays | F12, Ctrl+S: screenshot | Q/Esc: quit | window/level: [ ] "
          "move, , . narrow/widen, ; ' gamma, 0 reset");
      ImGui::EndTabItem();
    }
    ImGui::EndTabBar();
  }
  if (ImGui::Button("Screenshot (F12)")) v.screenshot_requested = true;
  if (!last_screenshot.empty()) ImGui::TextUnformatted(last_screenshot.c_str());
  const ImVec2 at = ImGui::GetWindowPos(), size = ImGui::GetWindowSize();
  v.panel_box = {at.x, at.y, size.x, size.y};
  ImGui::PopTextWrapPos();
  ImGui::End();
  return picked;
}

// Hands the old renderer's tiles back to the streamer and creates the new one: the streamer
// offers them again (from its cache) and the new renderer uploads them over the next frames.
Result<std::unique_ptr<Renderer>> switchRenderer(RendererKind kind, const ImageInfo& info,
                                                 TileStreamer& streamer,
                                                 std::unordered_set<TileId, TileIdHash>& resident) {
  ApplyResult handed_back;
  handed_back.dropped.assign(resident.begin(), resident.end());
  streamer.acknowledge(handed_back);
  resident.clear();
  return createRenderer(kind, info);
}

// Opens the archive to view, through a simulated link with --link (`over_link` then true).
Result<std::shared_ptr<Archive>> openViewedArchive(const ViewArgs& args, bool& over_link) {
  over_link = !args.link.empty();
  if (!over_link) return openArchive(args.archive);
  Result<LinkModel> model = parseLinkModel(args.link);
  if (!model) return forwardError(model);
  Result<std::shared_ptr<ByteSource>> inner = openByteSource(args.archive);
  if (!inner) return forwardError(inner);
  return Archive::open(makeThrottledSource(*inner, *model));
}

// The first view (the whole image, in the fly-over with --perspective), the overlays asked
// for, and the window's callbacks, which reach `v` through the window's user pointer.
void startViewer(Viewer& v, const ViewArgs& args) {
  v.view.image = args.image;
  int fw = 0, fh = 0;
  glfwGetFramebufferSize(v.window, &fw, &fh);
  v.view.ortho = fitImage(v.info, uint32_t(std::max(1, fw)), uint32_t(std::max(1, fh)));
  if (args.perspective) togglePerspective(v);
  for (const std::string& name : args.overlays) {
    v.overlays.levels |= name == "levels";
    v.overlays.clip_regions |= name == "clip";
    v.overlays.grid |= name == "grid";
  }
  glfwSetWindowUserPointer(v.window, &v);
  glfwSetScrollCallback(v.window, onScroll);
  glfwSetMouseButtonCallback(v.window, onMouseButton);
  glfwSetCursorPosCallback(v.window, onCursor);
  glfwSetKeyCallback(v.window, onKey);
}

// What the frames of a running viewer share. Render thread only.
struct ViewerLoop {
  const ViewArgs& args;
  Viewer& v;
  TileStreamer& streamer;
  std::unique_ptr<Renderer> renderer;
  ViewOverlay& overlay;
  size_t cache_budget_bytes = 0;
  /// The tiles the renderer holds, for the level overlay.
  std::unordered_set<TileId, TileIdHash> resident;
  FrameFigures figures;
  std::string last_screenshot;  ///< its path, or the error that kept it from being written
  int exit_code = kExitOk;
  Clock::time_point started;
};

// One frame of the runtime: update, apply (acknowledged), draw, overlays.
const FrameUpdate& streamAndDraw(ViewerLoop& loop, Clock::time_point now) {
  Viewer& v = loop.v;
  const FrameUpdate& update = loop.streamer.update(v.view);
  loop.streamer.acknowledge(loop.renderer->apply(update));
  // The renderer may drop tiles of its own accord (a clipmap slot taken by a newer tile),
  // so the set keeps only what it still holds.
  for (const auto& tile : update.uploads) loop.resident.insert(tile->id);
  std::erase_if(loop.resident, [&](const TileId& id) { return !loop.renderer->resident(id); });
  loop.figures.streaming_ms = update.report.update_ms + loop.renderer->stats().apply_cpu_ms;
  loop.figures.read_rate.add(now, update.report.bytes_read_total);
  loop.renderer->setDisplayWindow(v.display);  // uniforms only; keys may have changed it
  loop.renderer->draw(v.view);
  loop.overlay.draw(v.view, v.info, v.overlays, update, loop.resident, *loop.renderer);
  return update;
}

// --frames: the last frame waits for the loader to settle (or 10 s) so its screenshot shows
// the image at full detail rather than whatever had loaded by then.
bool lastScriptedFrame(const ViewerLoop& loop, uint64_t frame, const FrameReport& r,
                       Clock::time_point now) {
  if (loop.args.frames == 0 || frame + 1 < loop.args.frames) return false;
  const bool settled = r.queue_length == 0 && r.in_flight == 0 && r.uploads == 0 &&
                       r.fully_covered && r.coverage_desired >= 1;
  return settled || now - loop.started > std::chrono::seconds(10);
}

void saveScreenshot(ViewerLoop& loop) {
  const std::string path = nextScreenshotPath(loop.args.screenshot_dir);
  Result<void> written = writePng(loop.renderer->readPixels(), path);
  if (written) {
    loop.last_screenshot = path;
    std::fprintf(stderr, "tessera view: wrote %s\n", path.c_str());
  } else {
    loop.last_screenshot = written.error().message;
    loop.exit_code = reportError(written.error());
  }
}

// The picture to the window with the panel over it; returns the renderer the panel picked.
RendererKind presentFrame(ViewerLoop& loop, const FrameUpdate& update, int fw, int fh) {
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  glViewport(0, 0, fw, fh);
  loop.renderer->present(uint32_t(fw), uint32_t(fh));
  ImGui_ImplOpenGL3_NewFrame();
  ImGui_ImplGlfw_NewFrame();
  ImGui::NewFrame();
  RendererKind picked = loop.renderer->kind();
  if (loop.v.show_panel)
    picked = drawPanel(loop.v, loop.args.archive, update, loop.streamer, *loop.renderer,
                       loop.figures, loop.cache_budget_bytes, loop.last_screenshot, fw, fh);
  ImGui::Render();
  ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
  glfwSwapBuffers(loop.v.window);
  return picked;
}

// Frames until the window closes (or --frames ends). Returns the exit code.
int runViewerLoop(ViewerLoop& loop) {
  Viewer& v = loop.v;
  Clock::time_point last_frame = Clock::now();
  loop.started = last_frame;
  for (uint64_t frame = 0; !glfwWindowShouldClose(v.window); ++frame) {
    glfwPollEvents();
    const Clock::time_point now = Clock::now();
    const double dt_s = std::chrono::duration<double>(now - last_frame).count();
    last_frame = now;
    applyHeldKeys(v, std::min(dt_s, 0.1));
    int fw = 0, fh = 0;
    glfwGetFramebufferSize(v.window, &fw, &fh);
    if (fw <= 0 || fh <= 0) {  // minimised: nothing to draw until the window comes back
      glfwWaitEventsTimeout(0.1);
      continue;
    }
    v.view.ortho.viewport_w = v.view.perspective.viewport_w = uint32_t(fw);
    v.view.ortho.viewport_h = v.view.perspective.viewport_h = uint32_t(fh);

    const FrameUpdate& update = streamAndDraw(loop, now);
    const bool last = lastScriptedFrame(loop, frame, update.report, now);
    if (last) v.screenshot_requested = true;
    if (v.screenshot_requested) {
      v.screenshot_requested = false;
      saveScreenshot(loop);
    }
    const RendererKind picked = presentFrame(loop, update, fw, fh);
    loop.figures.push(std::chrono::duration<double, std::milli>(Clock::now() - now).count(),
                      update.report.link_bytes_per_s);
    if (picked != loop.renderer->kind()) {
      Result<std::unique_ptr<Renderer>> switched =
          switchRenderer(picked, v.info, loop.streamer, loop.resident);
      if (!switched) return reportError(switched.error());
      loop.renderer = std::move(*switched);
    }
    if (last) {
      // For tests: how much of the picture the panel covers.
      if (v.show_panel)
        std::fprintf(stderr, "tessera view: panel at %.0f,%.0f, %.0fx%.0f of %dx%d\n",
                     v.panel_box.x, v.panel_box.y, v.panel_box.width, v.panel_box.height, fw, fh);
      break;
    }
  }
  return loop.exit_code;
}

}  // namespace

int runView(const ViewArgs& args) {
  if (isSceneArchive(args.archive)) return runSceneView(args);
  uint32_t window_w = 0, window_h = 0;
  if (std::sscanf(args.size.c_str(), "%ux%u", &window_w, &window_h) != 2 || window_w == 0 ||
      window_h == 0 || window_w > 16384 || window_h > 16384)
    return reportError({ErrorCode::kInvalidArgument,
                        fmt::format("--size {}: expected WxH, e.g. 1280x720", args.size)});
  const std::optional<RendererKind> kind = rendererNamed(args.renderer);
  if (!kind)
    return reportError({ErrorCode::kInvalidArgument,
                        fmt::format("--renderer {}: no such renderer", args.renderer)});
  bool over_link = false;
  Result<std::shared_ptr<Archive>> archive = openViewedArchive(args, over_link);
  if (!archive) return reportError(archive.error());
  if (args.image >= (*archive)->images().size())
    return reportError(
        {ErrorCode::kInvalidArgument, fmt::format("{}: no image {} (it has {})", args.archive,
                                                  args.image, (*archive)->images().size())});
  const ImageInfo info = (*archive)->images()[args.image];
  Result<DisplayWindow> display =
      displayWindowFromOptions(**archive, args.image, args.window, args.gamma);
  if (!display) return reportError(display.error());

  // The window first: without a display nothing else is worth starting.
  Result<std::unique_ptr<GlContext>> context =
      GlContext::createWindow(window_w, window_h, fmt::format("tessera view: {}", args.archive));
  if (!context) return reportError(context.error());
  GLFWwindow* window = (*context)->window()->glfw;
  glfwSwapInterval(1);

  StreamerOptions options;
  options.cache_budget_bytes = args.cache_mib << 20;
  // Wherever reads cross a network, simulated or real: the remote tuning (docs/runtime.md).
  if (over_link || isRemoteUri(args.archive)) tuneForRemoteSource(options);
  if (args.adaptive != "auto") options.adaptive.enabled = args.adaptive == "on";
  if (Result<EgressBudget> egress = parseEgressBudget(args.egress); egress)
    options.adaptive.egress = *egress;  // checked when the command line was parsed
  Result<std::unique_ptr<TileStreamer>> streamer = TileStreamer::create(*archive, options);
  if (!streamer) return reportError(streamer.error());
  Result<std::unique_ptr<Renderer>> renderer = createRenderer(*kind, info);
  if (!renderer) return reportError(renderer.error());
  Result<std::unique_ptr<ViewOverlay>> overlay = ViewOverlay::create();
  if (!overlay) return reportError(overlay.error());

  Viewer v;
  v.window = window;
  v.info = info;
  v.display = v.initial_display = *display;
  startViewer(v, args);
  ImGuiSession imgui(window);
  ViewerLoop loop{args, v, **streamer, std::move(*renderer), **overlay};
  loop.cache_budget_bytes = options.cache_budget_bytes;
  return runViewerLoop(loop);
}

void registerViewCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<ViewArgs>();
  CLI::App* cmd = app.add_subcommand(
      "view", "Open an archive in a window: pan, zoom, fly over, overlays (docs/view.md)");
  cmd->add_option("archive", args->archive, kArchiveArgumentHelp)->required();
  cmd->add_option("--renderer", args->renderer, "tile-quads or clipmap")
      ->check(CLI::IsMember({"tile-quads", "clipmap"}))
      ->capture_default_str();
  cmd->add_option("--image", args->image, "Image index")->capture_default_str();
  cmd->add_option("--window", args->window, kWindowOptionHelp)->capture_default_str();
  cmd->add_option("--gamma", args->gamma, kGammaOptionHelp)->capture_default_str();
  cmd->add_option("--size", args->size, "Window size WxH")->capture_default_str();
  cmd->add_option("--cache-mib", args->cache_mib, "Tile cache budget in MiB")
      ->capture_default_str();
  cmd->add_flag("--perspective", args->perspective, "Start in the perspective fly-over");
  cmd->add_option("--overlays", args->overlays,
                  "Overlays on from the start: levels, clip, grid (comma-separated); for a "
                  "scene levels, nodes, cell")
      ->delimiter(',')
      ->check(CLI::IsMember({"levels", "clip", "grid", "nodes", "cell"}));
  cmd->add_option("--screenshot-dir", args->screenshot_dir, "Folder for tessera-screenshot-<n>.png")
      ->capture_default_str();
  // For tests and scripted runs: an empty group hides it from --help.
  cmd->add_option("--link", args->link,
                  "Read the archive through a simulated network link RATE:RTT, e.g. 20mbit:40ms");
  cmd->add_option("--adaptive", args->adaptive,
                  "Adaptive scheduling: auto (on with --link or a URL), on, off")
      ->check(CLI::IsMember({"auto", "on", "off"}))
      ->capture_default_str();
  cmd->add_option("--egress", args->egress,
                  "What adaptive scheduling fetches beyond the view: default (at most 1.5x the "
                  "view's bytes and requests), metered (only the view), unbounded, or a factor")
      ->check(egressSpecValidator())
      ->capture_default_str();
  cmd->add_option("--frames", args->frames,
                  "Quit after this many frames, once loading settles, writing a screenshot")
      ->group("");
  cmd->callback([args, &exit_code] { exit_code = runView(*args); });
}

}  // namespace tessera::cli
