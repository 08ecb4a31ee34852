// The scene renderer (docs/scenes.md, "Rendering"): the streamer's drawable objects with their
// meshes (uploaded once each) and base-colour textures (the mirror in scene_textures.cpp),
// depth-tested, in the camera frame of the streamer's PerspectiveView.
#include <tessera/scene_render.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>

#include <fmt/format.h>

#include "gl/gl_objects.h"
#include "scene_textures.h"

namespace tessera {

namespace {

using Clock = std::chrono::steady_clock;

// Positions are relative to the eye (the model-view-projection is composed in double on the
// CPU), so 32-bit floats keep their precision kilometres from the scene's origin.
const char* kSceneVertex = R"(#version 450 core
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
layout(location = 2) in vec2 a_uv;
uniform mat4 u_mvp;
uniform mat3 u_normal_to_eye;
out vec2 v_uv;
out float v_shade;
void main() {
  gl_Position = u_mvp * vec4(a_position, 1.0);
  v_uv = a_uv;
  // A headlight: faces turned towards the eye are brighter; no normals, no shading.
  vec3 n = u_normal_to_eye * a_normal;
  float len = length(n);
  v_shade = len > 0.0 ? 0.55 + 0.45 * abs(n.z / len) : 1.0;
}
)";

const char* kSceneFragment = R"(#version 450 core
in vec2 v_uv;
in float v_shade;
uniform sampler2D u_texture;
uniform bool u_textured;
uniform vec4 u_factor;
uniform vec4 u_tint;
out vec4 colour;
void main() {
  vec4 c = u_factor;
  if (u_textured) c *= texture(u_texture, v_uv);
  vec3 shaded = c.rgb * v_shade;
  colour = vec4(mix(shaded, u_tint.rgb, u_tint.a), 1.0);
}
)";

const char* kBoxVertex = R"(#version 450 core
layout(location = 0) in vec3 a_corner;
uniform mat4 u_vp;
uniform vec3 u_min;
uniform vec3 u_size;
void main() { gl_Position = u_vp * vec4(u_min + a_corner * u_size, 1.0); }
)";

const char* kBoxFragment = R"(#version 450 core
uniform vec4 u_colour;
out vec4 colour;
void main() { colour = u_colour; }
)";

/// Column-major 4x4 in double, composed before the one conversion to float.
using Mat4 = std::array<double, 16>;

Mat4 multiply(const Mat4& a, const Mat4& b) {
  Mat4 out{};
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r)
      for (int k = 0; k < 4; ++k) out[c * 4 + r] += a[k * 4 + r] * b[c * 4 + k];
  return out;
}

/// Near and far planes bracketing the scene's box from the eye: far at its furthest corner,
/// near as far out as the box allows, but no closer than far / 2^16 (24-bit depth).
std::array<double, 2> depthRange(const PerspectiveView& camera, const Box3& bounds) {
  const double eye[3] = {camera.eye_x, camera.eye_y, camera.eye_z};
  double far_sq = 0, near_sq = 0;
  for (int a = 0; a < 3; ++a) {
    const double d = std::max(std::abs(bounds.min[a] - eye[a]), std::abs(bounds.max[a] - eye[a]));
    far_sq += d * d;
    const double outside = std::max({0.0, bounds.min[a] - eye[a], eye[a] - bounds.max[a]});
    near_sq += outside * outside;
  }
  const double far = std::max(1e-3, std::sqrt(far_sq) * 1.01);
  const double near = std::max(far / 65536, std::sqrt(near_sq) * 0.99);
  return {near, far};
}

/// World (relative to the eye) to clip space: the camera basis as the view, then the
/// perspective of its field of view (OpenGL conventions).
Mat4 viewProjectionOf(const PerspectiveView& camera, const Box3& bounds) {
  const CameraBasis b = cameraBasis(camera);
  // Rows of the view: screen x, screen y, and -forward (GL looks down -z).
  const Mat4 view = {b.right.x,
                     b.up.x,
                     -b.forward.x,
                     0,
                     b.right.y,
                     b.up.y,
                     -b.forward.y,
                     0,
                     b.right.z,
                     b.up.z,
                     -b.forward.z,
                     0,
                     0,
                     0,
                     0,
                     1};
  const double aspect = double(std::max(1u, camera.viewport_w)) / std::max(1u, camera.viewport_h);
  const double f = 1 / std::tan(camera.fov_y_rad / 2);
  const auto [near, far] = depthRange(camera, bounds);
  Mat4 projection{};
  projection[0] = f / aspect;
  projection[5] = f;
  projection[10] = (far + near) / (near - far);
  projection[11] = -1;
  projection[14] = 2 * far * near / (near - far);
  return multiply(projection, view);
}

/// An object's transform (row-major 3x4, object to world) with the eye subtracted.
Mat4 objectToEyeRelative(const SceneObject& object, const PerspectiveView& camera) {
  const auto& t = object.transform;
  return {t[0],
          t[4],
          t[8],
          0,
          t[1],
          t[5],
          t[9],
          0,
          t[2],
          t[6],
          t[10],
          0,
          t[3] - camera.eye_x,
          t[7] - camera.eye_y,
          t[11] - camera.eye_z,
          1};
}

std::array<float, 16> toFloat(const Mat4& m) {
  std::array<float, 16> out;
  for (int i = 0; i < 16; ++i) out[i] = float(m[i]);
  return out;
}

std::array<float, 4> unpackRgba(uint32_t rgba) {
  return {float(rgba & 0xFF) / 255, float((rgba >> 8) & 0xFF) / 255,
          float((rgba >> 16) & 0xFF) / 255, float(rgba >> 24) / 255};
}

/// One mesh on the GPU: interleaved position, normal and uv, and its indices.
struct GpuMesh {
  gl::VertexArray vertex_array;
  gl::Buffer vertices;
  gl::Buffer indices;
  GLsizei index_count = 0;
};

GpuMesh uploadMesh(const MeshData& mesh) {
  const size_t count = mesh.positions.size() / 3;
  std::vector<float> interleaved(count * 8, 0.0f);
  for (size_t v = 0; v < count; ++v) {
    float* out = &interleaved[v * 8];
    std::copy_n(&mesh.positions[v * 3], 3, out);
    if (mesh.normals.size() >= (v + 1) * 3) std::copy_n(&mesh.normals[v * 3], 3, out + 3);
    if (mesh.uv0.size() >= (v + 1) * 2) std::copy_n(&mesh.uv0[v * 2], 2, out + 6);
  }
  GpuMesh gpu;
  gpu.vertices = gl::createBuffer();
  glNamedBufferStorage(gpu.vertices.get(), GLsizeiptr(std::max<size_t>(1, interleaved.size()) * 4),
                       interleaved.empty() ? nullptr : interleaved.data(), 0);
  gpu.indices = gl::createBuffer();
  glNamedBufferStorage(gpu.indices.get(), GLsizeiptr(std::max<size_t>(1, mesh.indices.size()) * 4),
                       mesh.indices.empty() ? nullptr : mesh.indices.data(), 0);
  gpu.vertex_array = gl::createVertexArray();
  const GLuint vao = gpu.vertex_array.get();
  glVertexArrayVertexBuffer(vao, 0, gpu.vertices.get(), 0, 8 * sizeof(float));
  glVertexArrayElementBuffer(vao, gpu.indices.get());
  const GLuint sizes[3] = {3, 3, 2}, offsets[3] = {0, 3, 6};
  for (GLuint a = 0; a < 3; ++a) {
    glEnableVertexArrayAttrib(vao, a);
    glVertexArrayAttribFormat(vao, a, GLint(sizes[a]), GL_FLOAT, GL_FALSE,
                              offsets[a] * sizeof(float));
    glVertexArrayAttribBinding(vao, a, 0);
  }
  gpu.index_count = GLsizei(mesh.indices.size());
  return gpu;
}

/// The 12 edges of the unit cube as line endpoints.
std::vector<float> unitCubeEdges() {
  std::vector<float> out;
  for (int axis = 0; axis < 3; ++axis)
    for (int i = 0; i < 4; ++i) {
      float a[3], b[3];
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      a[axis] = 0, b[axis] = 1;
      a[u] = b[u] = float(i & 1);
      a[v] = b[v] = float(i >> 1);
      out.insert(out.end(), a, a + 3);
      out.insert(out.end(), b, b + 3);
    }
  return out;
}

}  // namespace

uint32_t sceneLevelTint(uint32_t level) {
  static const uint32_t kTints[] = {0xFF30C030u, 0xFF30E0C0u, 0xFF30E0F0u, 0xFF3090F0u,
                                    0xFF3030E0u, 0xFF9030D0u, 0xFFD03090u, 0xFFE0E0E0u};
  return kTints[std::min<size_t>(level, std::size(kTints) - 1)];
}

struct SceneRenderer::Impl {
  std::shared_ptr<const SceneArchive> archive;
  SceneRenderOptions options;
  std::unique_ptr<gl::SceneTextureMirror> textures;
  std::vector<GpuMesh> meshes;  ///< by mesh index; empty vertex_array until uploaded
  gl::Program program, box_program;
  GLint u_mvp = -1, u_normal = -1, u_textured = -1, u_factor = -1, u_tint = -1;
  GLint u_box_vp = -1, u_box_min = -1, u_box_size = -1, u_box_colour = -1;
  GpuMesh cube;
  gl::ColourTarget target;
  std::vector<uint32_t> frame_textures;  ///< scratch: distinct textures of a frame
  std::vector<uint8_t> texture_seen;     ///< scratch, by texture

  void uploadFrame(const SceneStreamer& streamer, SceneDrawStats& stats);
  void drawObjects(const SceneStreamer& streamer, const PerspectiveView& camera,
                   const Mat4& view_projection, const SceneOverlays& overlays,
                   SceneDrawStats& stats);
  void drawBoxes(const PerspectiveView& camera, const Mat4& view_projection,
                 const std::vector<OverlayBox>& boxes);
};

Result<std::unique_ptr<SceneRenderer>> SceneRenderer::create(
    std::shared_ptr<const SceneArchive> archive, const SceneRenderOptions& options) {
  auto impl = std::make_unique<Impl>();
  Result<std::vector<SceneTexture>> records = archive->textures(0, archive->summary().textures);
  if (!records) return forwardError(records);
  Result<gl::Program> program = gl::linkProgram("scene", kSceneVertex, kSceneFragment);
  if (!program) return forwardError(program);
  Result<gl::Program> box_program = gl::linkProgram("scene boxes", kBoxVertex, kBoxFragment);
  if (!box_program) return forwardError(box_program);
  impl->program = std::move(*program);
  impl->box_program = std::move(*box_program);
  const GLuint p = impl->program.get(), b = impl->box_program.get();
  impl->u_mvp = glGetUniformLocation(p, "u_mvp");
  impl->u_normal = glGetUniformLocation(p, "u_normal_to_eye");
  impl->u_textured = glGetUniformLocation(p, "u_textured");
  impl->u_factor = glGetUniformLocation(p, "u_factor");
  impl->u_tint = glGetUniformLocation(p, "u_tint");
  glProgramUniform1i(p, glGetUniformLocation(p, "u_texture"), 0);
  impl->u_box_vp = glGetUniformLocation(b, "u_vp");
  impl->u_box_min = glGetUniformLocation(b, "u_min");
  impl->u_box_size = glGetUniformLocation(b, "u_size");
  impl->u_box_colour = glGetUniformLocation(b, "u_colour");
  MeshData cube;
  cube.positions = unitCubeEdges();
  for (uint32_t i = 0; i < cube.positions.size() / 3; ++i) cube.indices.push_back(i);
  impl->cube = uploadMesh(cube);
  impl->meshes.resize(archive->summary().meshes);
  impl->texture_seen.assign(records->size(), 0);
  impl->textures = std::make_unique<gl::SceneTextureMirror>(archive, std::move(*records), options);
  impl->archive = std::move(archive);
  impl->options = options;
  return std::unique_ptr<SceneRenderer>(new SceneRenderer(std::move(impl)));
}

SceneRenderer::SceneRenderer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
SceneRenderer::~SceneRenderer() = default;

void SceneRenderer::Impl::uploadFrame(const SceneStreamer& streamer, SceneDrawStats& stats) {
  textures->beginFrame();
  frame_textures.clear();
  for (uint32_t index : streamer.drawableObjects()) {
    const SceneObject* object = streamer.object(index);
    if (!object) continue;
    if (object->mesh < meshes.size() && !meshes[object->mesh].vertex_array) {
      if (const MeshData* mesh = streamer.mesh(object->mesh)) {
        meshes[object->mesh] = uploadMesh(*mesh);
        ++stats.meshes_uploaded;
      }
    }
    const uint32_t texture = object->textures[size_t(TextureSlot::kBaseColor)];
    if (texture == kNoTexture || texture >= texture_seen.size() || texture_seen[texture]) continue;
    texture_seen[texture] = 1;
    if (textures->require(texture, streamer)) frame_textures.push_back(texture);
  }
  for (uint32_t texture : frame_textures) textures->refine(texture, streamer);
  textures->flush(stats);
  for (uint32_t texture : frame_textures) {
    if (textures->sampledLevel(texture) > streamer.wantedLevel(texture) &&
        !options.all_levels_resident)
      ++stats.textures_below_wanted;
  }
  // Textures that failed require are not in frame_textures: clear every mark.
  std::fill(texture_seen.begin(), texture_seen.end(), 0);
}

void SceneRenderer::Impl::drawObjects(const SceneStreamer& streamer, const PerspectiveView& camera,
                                      const Mat4& view_projection, const SceneOverlays& overlays,
                                      SceneDrawStats& stats) {
  const CameraBasis b = cameraBasis(camera);
  const GLuint p = program.get();
  glUseProgram(p);
  for (uint32_t index : streamer.drawableObjects()) {
    const SceneObject* object = streamer.object(index);
    if (!object || object->mesh >= meshes.size() || !meshes[object->mesh].vertex_array) continue;
    const uint32_t texture = object->textures[size_t(TextureSlot::kBaseColor)];
    const bool textured = texture != kNoTexture;
    const GLuint handle = textured ? textures->handle(texture) : 0;
    if (textured && handle == 0) {
      ++stats.untextured_objects;  // never drawn without its texture: a hole, counted
      continue;
    }
    const std::array<float, 16> mvp =
        toFloat(multiply(view_projection, objectToEyeRelative(*object, camera)));
    glProgramUniformMatrix4fv(p, u_mvp, 1, GL_FALSE, mvp.data());
    // Normals to eye space: the view's rows times the object's 3x3 (no non-uniform scale
    // assumed; the shader normalises).
    const auto& t = object->transform;
    const double rows[3][3] = {{-b.right.x, -b.right.y, -b.right.z},
                               {b.up.x, b.up.y, b.up.z},
                               {-b.forward.x, -b.forward.y, -b.forward.z}};
    float normal[9];
    for (int c = 0; c < 3; ++c)
      for (int r = 0; r < 3; ++r)
        normal[c * 3 + r] = float(rows[r][0] * t[0 * 4 + c] + rows[r][1] * t[1 * 4 + c] +
                                  rows[r][2] * t[2 * 4 + c]);
    glProgramUniformMatrix3fv(p, u_normal, 1, GL_FALSE, normal);
    glProgramUniform1i(p, u_textured, textured ? 1 : 0);
    const std::array<float, 4> factor = unpackRgba(object->base_color_rgba);
    glProgramUniform4fv(p, u_factor, 1, factor.data());
    std::array<float, 4> tint{0, 0, 0, 0};
    if (overlays.level_tint && textured) {
      tint = unpackRgba(sceneLevelTint(textures->sampledLevel(texture)));
      tint[3] = 0.5f;
    }
    glProgramUniform4fv(p, u_tint, 1, tint.data());
    glBindTextureUnit(0, handle);
    glBindVertexArray(meshes[object->mesh].vertex_array.get());
    glDrawElements(GL_TRIANGLES, meshes[object->mesh].index_count, GL_UNSIGNED_INT, nullptr);
    ++stats.objects_drawn;
  }
  glBindVertexArray(0);
  glBindTextureUnit(0, 0);
}

void SceneRenderer::Impl::drawBoxes(const PerspectiveView& camera, const Mat4& view_projection,
                                    const std::vector<OverlayBox>& boxes) {
  if (boxes.empty()) return;
  const GLuint p = box_program.get();
  glUseProgram(p);
  const std::array<float, 16> vp = toFloat(view_projection);
  glProgramUniformMatrix4fv(p, u_box_vp, 1, GL_FALSE, vp.data());
  glBindVertexArray(cube.vertex_array.get());
  for (const OverlayBox& box : boxes) {
    const float min[3] = {float(box.box.min[0] - camera.eye_x),
                          float(box.box.min[1] - camera.eye_y),
                          float(box.box.min[2] - camera.eye_z)};
    const float size[3] = {box.box.max[0] - box.box.min[0], box.box.max[1] - box.box.min[1],
                           box.box.max[2] - box.box.min[2]};
    const std::array<float, 4> colour = unpackRgba(box.rgba);
    glProgramUniform3fv(p, u_box_min, 1, min);
    glProgramUniform3fv(p, u_box_size, 1, size);
    glProgramUniform4fv(p, u_box_colour, 1, colour.data());
    glDrawArrays(GL_LINES, 0, cube.index_count);
  }
  glBindVertexArray(0);
}

SceneDrawStats SceneRenderer::draw(const SceneStreamer& streamer, const PerspectiveView& camera,
                                   const SceneOverlays& overlays) {
  const auto started = Clock::now();
  Impl& s = *impl_;
  SceneDrawStats stats;
  s.uploadFrame(streamer, stats);
  s.target.bind(std::max(1u, camera.viewport_w), std::max(1u, camera.viewport_h), true);
  const std::array<float, 4> background = unpackRgba(s.options.background_rgba);
  glClearColor(background[0], background[1], background[2], background[3]);
  glClearDepth(1.0);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDisable(GL_BLEND);
  glDisable(GL_CULL_FACE);  // imported meshes' winding is not to be trusted
  const Mat4 view_projection = viewProjectionOf(camera, s.archive->summary().bounds);
  s.drawObjects(streamer, camera, view_projection, overlays, stats);
  s.drawBoxes(camera, view_projection, overlays.boxes);
  glDisable(GL_DEPTH_TEST);
  glUseProgram(0);
  glFlush();
  stats.sampled_texel_bytes = s.textures->sampledTexelBytes();
  stats.render_ms = std::chrono::duration<double, std::milli>(Clock::now() - started).count();
  return stats;
}

Picture SceneRenderer::readPixels() {
  Picture picture;
  impl_->target.read(picture.rgba);
  picture.width = impl_->target.width();
  picture.height = impl_->target.height();
  return picture;
}

void SceneRenderer::present(uint32_t window_width, uint32_t window_height) {
  impl_->target.blitToWindow(window_width, window_height);
}

uint32_t SceneRenderer::sampledLevel(uint32_t texture) const {
  return impl_->textures->sampledLevel(texture);
}

uint32_t SceneRenderer::readFailures() const {
  return impl_->textures->readFailures();
}

const std::string& SceneRenderer::firstReadError() const {
  return impl_->textures->firstReadError();
}

}  // namespace tessera
