// `tessera view SCENE.tess`: a window on a streamed scene with walk and fly controls and the
// overlays of docs/view.md, "Scenes" (resident level per object, R-tree node boxes).
#include "scene_view_command.h"

#include <GLFW/glfw3.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>

#include <fmt/format.h>

#include <tessera/gl.h>
#include <tessera/open.h>
#include <tessera/picture_file.h>
#include <tessera/scene.h>
#include <tessera/scene_render.h>
#include <tessera/scene_stream.h>

#include "cli.h"
#include "gl/window.h"
#include "scene_path.h"
#include "view_screenshot.h"

namespace tessera::cli {

namespace {

using Clock = std::chrono::steady_clock;

constexpr double kTurnRadPerPx = 0.004;
/// R-tree nodes drawn by the node overlay: the upper levels (a deep tree has thousands).
constexpr uint32_t kNodeOverlayDepth = 3;
/// The view-cell box: white, so it stands apart from the node boxes' level colours.
constexpr uint32_t kViewCellColour = 0xFFFFFFFFu;

/// What the window's callbacks change; read by the frame loop on the same thread.
struct SceneViewer {
  GLFWwindow* window = nullptr;
  ScenePose pose, home;
  double speed_m_s = 10;  ///< walking or flying speed, world units per second
  bool walk = true;       ///< walk: moves stay level; fly: forward follows the pitch
  SceneOverlays overlays;
  bool show_nodes = false;
  bool show_cell = false;
  bool screenshot_requested = false;
  bool dragging = false;
  double last_x = 0, last_y = 0;
};

SceneViewer& viewerOf(GLFWwindow* window) {
  return *static_cast<SceneViewer*>(glfwGetWindowUserPointer(window));
}

void onKey(GLFWwindow* window, int key, int, int action, int) {
  if (action != GLFW_PRESS) return;
  SceneViewer& v = viewerOf(window);
  switch (key) {
    case GLFW_KEY_ESCAPE: glfwSetWindowShouldClose(window, GLFW_TRUE); break;
    case GLFW_KEY_F: v.walk = !v.walk; break;
    case GLFW_KEY_L: v.overlays.level_tint = !v.overlays.level_tint; break;
    case GLFW_KEY_N: v.show_nodes = !v.show_nodes; break;
    case GLFW_KEY_C: v.show_cell = !v.show_cell; break;
    case GLFW_KEY_P:
    case GLFW_KEY_F12: v.screenshot_requested = true; break;
    case GLFW_KEY_HOME: v.pose = v.home; break;
    default: break;
  }
}

void onMouseButton(GLFWwindow* window, int button, int action, int) {
  SceneViewer& v = viewerOf(window);
  if (button != GLFW_MOUSE_BUTTON_LEFT) return;
  v.dragging = action == GLFW_PRESS;
  glfwGetCursorPos(window, &v.last_x, &v.last_y);
}

// Dragging turns the camera: yaw with x, pitch with y, pitch short of straight up or down.
void onCursor(GLFWwindow* window, double x, double y) {
  SceneViewer& v = viewerOf(window);
  if (!v.dragging) return;
  v.pose.yaw_rad += (x - v.last_x) * kTurnRadPerPx;
  const double limit = std::numbers::pi / 2 - 0.01;
  v.pose.pitch_rad = std::clamp(v.pose.pitch_rad - (y - v.last_y) * kTurnRadPerPx, -limit, limit);
  v.last_x = x;
  v.last_y = y;
}

// Held keys move the eye: W/S forward and back, A/D sideways, Q/E down and up; Shift is 4x.
void applyHeldKeys(SceneViewer& v, double dt_s) {
  auto held = [&](int key) { return glfwGetKey(v.window, key) == GLFW_PRESS ? 1.0 : 0.0; };
  const double forward = held(GLFW_KEY_W) - held(GLFW_KEY_S);
  const double right = held(GLFW_KEY_D) - held(GLFW_KEY_A);
  const double up = held(GLFW_KEY_E) - held(GLFW_KEY_Q);
  const double step = v.speed_m_s * dt_s * (held(GLFW_KEY_LEFT_SHIFT) ? 4 : 1);
  const double cy = std::cos(v.pose.yaw_rad), sy = std::sin(v.pose.yaw_rad);
  const double cp = v.walk ? 1 : std::cos(v.pose.pitch_rad);
  const double climb = v.walk ? 0 : std::sin(v.pose.pitch_rad);
  v.pose.x += step * (forward * sy * cp + right * cy);
  v.pose.z += step * (-forward * cy * cp + right * sy);
  v.pose.y += step * (forward * climb + up);
}

std::vector<OverlayBox> nodeBoxes(const std::vector<SceneNode>& nodes) {
  std::vector<OverlayBox> boxes;
  for (const SceneNode& node : nodes)
    if (node.depth <= kNodeOverlayDepth)
      boxes.push_back({node.bounds, sceneLevelTint(node.depth + 4)});
  return boxes;
}

/// The loop's state beyond the viewer's.
struct SceneViewLoop {
  const ViewArgs& args;
  SceneViewer& v;
  SceneStreamer& streamer;
  SceneRenderer& renderer;
  std::vector<OverlayBox> node_boxes;
  std::optional<CoverageHints> hints;  ///< the archive's coverage hints, for the view-cell overlay
  Box3 scene_bounds;
  int exit_code = kExitOk;
};

bool saveScreenshot(SceneViewLoop& loop) {
  const std::string path = nextScreenshotPath(loop.args.screenshot_dir);
  Result<void> written = writePng(loop.renderer.readPixels(), path);
  if (!written) {
    loop.exit_code = reportError(written.error());
    return false;
  }
  std::fprintf(stderr, "tessera view: wrote %s\n", path.c_str());
  return true;
}

int runSceneViewLoop(SceneViewLoop& loop) {
  SceneViewer& v = loop.v;
  const auto started = Clock::now();
  auto last_frame = started, last_title = started;
  for (uint64_t frame = 0; !glfwWindowShouldClose(v.window); ++frame) {
    glfwPollEvents();
    const auto now = Clock::now();
    applyHeldKeys(v, std::min(0.1, std::chrono::duration<double>(now - last_frame).count()));
    last_frame = now;
    int fw = 0, fh = 0;
    glfwGetFramebufferSize(v.window, &fw, &fh);
    if (fw <= 0 || fh <= 0) {  // minimised
      glfwWaitEventsTimeout(0.1);
      continue;
    }
    const PerspectiveView camera = perspectiveOf(v.pose, kSceneFovYRad, uint32_t(fw), uint32_t(fh));
    const SceneFrameStats stats = loop.streamer.update(camera);
    // Overlays: the node boxes, and the view cell whose coverage hints rank the loads.
    v.overlays.boxes = v.show_nodes ? loop.node_boxes : std::vector<OverlayBox>{};
    if (v.show_cell && loop.hints)
      if (std::optional<Box3> cell = viewCellBox(*loop.hints, camera, loop.scene_bounds))
        v.overlays.boxes.push_back({*cell, kViewCellColour});
    const SceneDrawStats drawn = loop.renderer.draw(loop.streamer, camera, v.overlays);
    const bool settled = stats.waiting_leaves == 0 && stats.missing_pixels == 0 &&
                         drawn.textures_below_wanted == 0 && stats.reads_started == 0;
    const bool last = loop.args.frames > 0 && frame + 1 >= loop.args.frames &&
                      (settled || now - started > std::chrono::seconds(10));
    if (v.screenshot_requested || last) {
      v.screenshot_requested = false;
      if (!saveScreenshot(loop)) return loop.exit_code;
    }
    loop.renderer.present(uint32_t(fw), uint32_t(fh));
    glfwSwapBuffers(v.window);
    if (now - last_title > std::chrono::milliseconds(500)) {
      last_title = now;
      glfwSetWindowTitle(
          v.window, fmt::format("tessera view: {} | {} | {} objects, {} texels, {} untextured",
                                loop.args.archive, v.walk ? "walk" : "fly", drawn.objects_drawn,
                                formatBytes(stats.texel_bytes + stats.pinned_texel_bytes),
                                stats.untextured_objects + drawn.untextured_objects)
                        .c_str());
    }
    if (last) break;
  }
  return loop.exit_code;
}

}  // namespace

int runSceneView(const ViewArgs& args) {
  uint32_t window_w = 0, window_h = 0;
  if (!parseViewport(args.size, window_w, window_h))
    return reportError({ErrorCode::kInvalidArgument,
                        fmt::format("--size {}: expected WxH, e.g. 1280x720", args.size)});
  Result<std::shared_ptr<ByteSource>> source = openByteSource(args.archive);
  if (!source) return reportError(source.error());
  Result<std::shared_ptr<SceneArchive>> archive = SceneArchive::open(*source);
  if (!archive) return reportError(archive.error());
  Result<std::vector<SceneNode>> nodes = (*archive)->allNodes();
  if (!nodes) return reportError(nodes.error());
  // The window first: without a display nothing else is worth starting.
  Result<std::unique_ptr<GlContext>> context =
      GlContext::createWindow(window_w, window_h, fmt::format("tessera view: {}", args.archive));
  if (!context) return reportError(context.error());
  Result<std::unique_ptr<SceneStreamer>> streamer = SceneStreamer::open(*archive);
  if (!streamer) return reportError(streamer.error());
  Result<std::unique_ptr<SceneRenderer>> renderer = SceneRenderer::create(*archive);
  if (!renderer) return reportError(renderer.error());

  SceneViewer v;
  v.window = (*context)->window()->glfw;
  const SceneSummary& scene = (*archive)->summary();
  v.home = v.pose = orbitPath(scene, 1).at(0);
  const Box3& b = scene.bounds;
  v.speed_m_s =
      std::max(1.0, std::max(double(b.max[0]) - b.min[0], double(b.max[2]) - b.min[2]) / 20);
  for (const std::string& overlay : args.overlays) {
    if (overlay == "levels") v.overlays.level_tint = true;
    if (overlay == "nodes") v.show_nodes = true;
    if (overlay == "cell") v.show_cell = true;
  }
  glfwSwapInterval(1);
  glfwSetWindowUserPointer(v.window, &v);
  glfwSetKeyCallback(v.window, onKey);
  glfwSetMouseButtonCallback(v.window, onMouseButton);
  glfwSetCursorPosCallback(v.window, onCursor);
  SceneViewLoop loop{args,         v,           **streamer, **renderer, nodeBoxes(*nodes),
                     std::nullopt, scene.bounds};
  // Hints are optional (an archive built without --coverage-hints has none).
  if ((*archive)->coverageHintsRange().length_bytes != 0) {
    Result<CoverageHints> hints = (*archive)->readCoverageHints();
    if (!hints) return reportError(hints.error());
    loop.hints = std::move(*hints);
  }
  const int code = runSceneViewLoop(loop);
  glfwSetWindowUserPointer(v.window, nullptr);
  return code;
}

}  // namespace tessera::cli
