#include "view_overlay.h"

#include <algorithm>
#include <cmath>
#include <optional>

#include "view_camera.h"

namespace tessera::cli {

namespace {

const char* const kVertexShader = R"(#version 450 core
layout(location = 0) in vec2 position;
layout(location = 1) in vec4 colour;
uniform mat4 view_projection;
out vec4 v_colour;
void main() {
  v_colour = colour;
  gl_Position = view_projection * vec4(position, 0.0, 1.0);
}
)";

const char* const kFragmentShader = R"(#version 450 core
in vec4 v_colour;
out vec4 fragment;
void main() { fragment = v_colour; }
)";

uint32_t packRgba(LevelColour c, float alpha) {
  auto byte = [](float v) { return uint32_t(std::lround(std::clamp(v, 0.0f, 1.0f) * 255)); };
  return byte(c.r) | byte(c.g) << 8 | byte(c.b) << 16 | byte(alpha) << 24;
}

// A level tile's area in level-0 pixels, cut to the image (the last row and column of tiles
// are padding past its edge).
struct PlaneRect {
  double x0, y0, x1, y1;
};

PlaneRect tileArea(const ImageInfo& info, uint32_t level, int64_t x0, int64_t y0, int64_t x1,
                   int64_t y1) {
  const double side = std::ldexp(double(info.tile_size_px), int(level));
  return {std::min(x0 * side, double(info.width_px)), std::min(y0 * side, double(info.height_px)),
          std::min(x1 * side, double(info.width_px)), std::min(y1 * side, double(info.height_px))};
}

}  // namespace

LevelColour levelColour(uint32_t level) {
  // Hues far enough apart that neighbouring levels never look alike: red for level 0, then
  // round the colour wheel.
  static const LevelColour kPalette[] = {
      {0.95f, 0.20f, 0.20f}, {1.00f, 0.60f, 0.10f}, {0.95f, 0.95f, 0.20f}, {0.30f, 0.85f, 0.30f},
      {0.20f, 0.85f, 0.90f}, {0.25f, 0.40f, 1.00f}, {0.65f, 0.30f, 0.95f}, {0.95f, 0.35f, 0.80f},
  };
  return kPalette[level % (sizeof(kPalette) / sizeof(kPalette[0]))];
}

Result<std::unique_ptr<ViewOverlay>> ViewOverlay::create() {
  std::unique_ptr<ViewOverlay> overlay(new ViewOverlay());
  TESSERA_ASSIGN_OR_RETURN(overlay->program_,
                           gl::linkProgram("view overlay", kVertexShader, kFragmentShader));
  overlay->view_projection_uniform_ =
      glGetUniformLocation(overlay->program_.get(), "view_projection");
  overlay->vertices_ = gl::createBuffer();
  overlay->vertex_array_ = gl::createVertexArray();
  const GLuint vao = overlay->vertex_array_.get();
  glVertexArrayVertexBuffer(vao, 0, overlay->vertices_.get(), 0, sizeof(Vertex));
  glEnableVertexArrayAttrib(vao, 0);
  glVertexArrayAttribFormat(vao, 0, 2, GL_FLOAT, GL_FALSE, offsetof(Vertex, x));
  glVertexArrayAttribBinding(vao, 0, 0);
  glEnableVertexArrayAttrib(vao, 1);
  glVertexArrayAttribFormat(vao, 1, 4, GL_UNSIGNED_BYTE, GL_TRUE, offsetof(Vertex, rgba));
  glVertexArrayAttribBinding(vao, 1, 0);
  return overlay;
}

void ViewOverlay::draw(const View& view, const ImageInfo& info, const OverlayOptions& options,
                       const FrameUpdate& update,
                       const std::unordered_set<TileId, TileIdHash>& resident,
                       const Renderer& renderer) {
  if (!options.any()) return;
  const ViewProjection transform = viewProjection(view, info);
  triangles_.clear();
  lines_.clear();
  auto vertex = [&](double x, double y, uint32_t rgba) {
    return Vertex{float(x - transform.anchor_x), float(y - transform.anchor_y), rgba};
  };
  auto quad = [&](const PlaneRect& r, uint32_t rgba) {
    if (r.x1 <= r.x0 || r.y1 <= r.y0) return;
    for (auto [x, y] : {std::pair{r.x0, r.y0},
                        {r.x1, r.y0},
                        {r.x1, r.y1},
                        {r.x0, r.y0},
                        {r.x1, r.y1},
                        {r.x0, r.y1}})
      triangles_.push_back(vertex(x, y, rgba));
  };
  auto line = [&](double x0, double y0, double x1, double y1, uint32_t rgba) {
    lines_.push_back(vertex(x0, y0, rgba));
    lines_.push_back(vertex(x1, y1, rgba));
  };
  auto outline = [&](const PlaneRect& r, uint32_t rgba) {
    line(r.x0, r.y0, r.x1, r.y0, rgba);
    line(r.x1, r.y0, r.x1, r.y1, rgba);
    line(r.x1, r.y1, r.x0, r.y1, rgba);
    line(r.x0, r.y1, r.x0, r.y0, rgba);
  };
  const uint32_t desired = update.report.desired_level;

  if (options.levels) {
    // Each quarter of a resident tile is drawn by that tile unless its child there is resident
    // too (then the child, or one finer still, draws it): tinting the quarters that no
    // resident child covers colours every area once, by the level that draws it. Levels
    // finer than the desired one are never drawn, so they stop the descent.
    for (const TileId& id : resident) {
      if (id.image != view.image || id.level < desired) continue;
      const uint32_t rgba = packRgba(levelColour(id.level), 0.45f);
      if (id.level == desired) {
        quad(tileArea(info, id.level, id.x, id.y, id.x + 1, id.y + 1), rgba);
        continue;
      }
      for (uint32_t q = 0; q < 4; ++q) {
        const TileId child{id.image, id.level - 1, id.x * 2 + (q & 1), id.y * 2 + (q >> 1)};
        if (renderer.resident(child)) continue;
        quad(tileArea(info, child.level, child.x, child.y, child.x + 1, child.y + 1), rgba);
      }
    }
  }

  if (options.grid) {
    const uint32_t rgba = packRgba({1, 1, 1}, 0.55f);
    for (const FrameUpdate::LevelRegion& r : update.regions) {
      if (r.level != desired || r.region.empty()) continue;
      const PlaneRect area =
          tileArea(info, r.level, r.region.x0, r.region.y0, r.region.x1, r.region.y1);
      const double side = std::ldexp(double(info.tile_size_px), int(r.level));
      for (int64_t x = r.region.x0; x <= r.region.x1; ++x)
        line(std::min(x * side, area.x1), area.y0, std::min(x * side, area.x1), area.y1, rgba);
      for (int64_t y = r.region.y0; y <= r.region.y1; ++y)
        line(area.x0, std::min(y * side, area.y1), area.x1, std::min(y * side, area.y1), rgba);
    }
    outline({0, 0, double(info.width_px), double(info.height_px)}, packRgba({1, 1, 1}, 0.9f));
  }

  if (options.clip_regions) {
    for (const FrameUpdate::LevelRegion& r : update.regions) {
      if (r.region.empty()) continue;
      outline(tileArea(info, r.level, r.region.x0, r.region.y0, r.region.x1, r.region.y1),
              packRgba(levelColour(r.level), 1.0f));
    }
    // The view's footprint on the plane: the screen's border walked round, each point cast on
    // the plane; a perspective border above the horizon has no footprint and breaks the loop.
    constexpr int kStepsPerEdge = 32;
    const double w = view.viewportWidth(), h = view.viewportHeight();
    std::vector<std::optional<PlanePoint>> ring;
    for (int edge = 0; edge < 4; ++edge) {
      for (int i = 0; i < kStepsPerEdge; ++i) {
        const double t = double(i) / kStepsPerEdge;
        const double sx = edge == 0 ? t * w : edge == 1 ? w : edge == 2 ? (1 - t) * w : 0;
        const double sy = edge == 0 ? 0 : edge == 1 ? t * h : edge == 2 ? h : (1 - t) * h;
        ring.push_back(planeAt(view, sx, sy));
      }
    }
    const uint32_t white = packRgba({1, 1, 1}, 1.0f);
    for (size_t i = 0; i < ring.size(); ++i) {
      const auto& a = ring[i];
      const auto& b = ring[(i + 1) % ring.size()];
      if (a && b) line(a->x, a->y, b->x, b->y, white);
    }
  }

  const size_t triangle_vertices = triangles_.size();
  std::vector<Vertex>& all = triangles_;
  all.insert(all.end(), lines_.begin(), lines_.end());
  if (all.empty()) return;
  // Orphaned every frame: the driver hands a fresh store instead of waiting for the last draw.
  glNamedBufferData(vertices_.get(), GLsizeiptr(all.size() * sizeof(Vertex)), all.data(),
                    GL_STREAM_DRAW);
  glProgramUniformMatrix4fv(program_.get(), view_projection_uniform_, 1, GL_FALSE,
                            transform.matrix);
  glUseProgram(program_.get());
  glBindVertexArray(vertex_array_.get());
  glEnable(GL_BLEND);
  glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
  glDisable(GL_DEPTH_TEST);
  if (triangle_vertices) glDrawArrays(GL_TRIANGLES, 0, GLsizei(triangle_vertices));
  if (!lines_.empty()) glDrawArrays(GL_LINES, GLsizei(triangle_vertices), GLsizei(lines_.size()));
  glDisable(GL_BLEND);
  glBindVertexArray(0);
  glUseProgram(0);
}

}  // namespace tessera::cli
