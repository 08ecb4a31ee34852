// GpuCompositor: procedural tiles composited in a fragment shader (docs/procedural.md, "GPU
// compositing"). The CPU runs the per-instance setup through the procedural module's own code
// (setupInstance, instanceRect, layerTaps) and uploads its integers; the shader
// (gpu_compositor_shader.h) does the per-texel integer arithmetic of compositeTile.
#include <algorithm>
#include <cstring>

#include <fmt/format.h>

#include <tessera/gl.h>

#include "gl/gl_objects.h"
#include "gpu_compositor_shader.h"
#include "procedural/kernel.h"

namespace tessera {

using namespace detail;

struct GpuCompositor::Impl {
  std::shared_ptr<const BrushSet> brushes;
  /// Texel offset of each brush's image's mip in the brush texel buffer: [brush][image][mip].
  std::vector<std::vector<std::vector<uint32_t>>> mip_offsets;
  /// Byte offset of each layer mip in the layer buffer: [0] height, [1] slope.
  std::vector<uint32_t> layer_offsets[2];
  gl::Program program;
  gl::VertexArray vertex_array;
  gl::Buffer brush_texels, layer_bytes, mask_tables, setups, params, layer_taps;
  gl::Texture target;
  gl::Framebuffer framebuffer;
  uint32_t target_side = 0;
  GLint max_block_bytes = 0;
  // Per-tile staging, kept to reuse the allocations.
  std::vector<int64_t> setup_values;
  std::vector<int32_t> param_values;
  std::vector<int32_t> tap_values;

  Result<void> upload();
  void uploadLayer(const LayerTaps& probe, const TileGeometry& tile, const ValidRect& rect);
  void draw(const TileGeometry& tile, const ValidRect& rect, size_t instances, Image& out);
};

namespace {

/// glNamedBufferData of a vector, at least 4 bytes (an empty storage buffer is an error).
template <typename T>
void fill(const gl::Buffer& buffer, const std::vector<T>& values) {
  static const T kPadding[2] = {};
  if (values.empty())
    glNamedBufferData(buffer.get(), sizeof(kPadding), kPadding, GL_STREAM_DRAW);
  else
    glNamedBufferData(buffer.get(), GLsizeiptr(values.size() * sizeof(T)), values.data(),
                      GL_STREAM_DRAW);
}

}  // namespace

Result<void> GpuCompositor::Impl::upload() {
  const BrushSet::Impl& set = brushes->impl();
  std::vector<uint8_t> texels;  // RGBA8 texels, one uint each in the shader
  std::vector<uint32_t> tables;
  for (const PreparedBrush& brush : set.prepared) {
    auto& images = mip_offsets.emplace_back();
    for (const ImagePyramid& image : brush.images) {
      auto& mips = images.emplace_back();
      for (const MipLevel& mip : image.mips) {
        mips.push_back(uint32_t(texels.size() / 4));
        texels.insert(texels.end(), mip.texels.begin(), mip.texels.end());
      }
    }
    tables.insert(tables.end(), brush.mask_lut.begin(), brush.mask_lut.end());
  }
  std::vector<uint8_t> layers;
  const LayerPyramid* pyramids[2] = {&set.height, &set.slope};
  for (int l = 0; l < 2; ++l) {
    for (const MipLevel& mip : pyramids[l]->mips) {
      layer_offsets[l].push_back(uint32_t(layers.size()));
      layers.insert(layers.end(), mip.texels.begin(), mip.texels.end());
    }
  }
  layers.resize((layers.size() + 3) & ~size_t(3));
  glGetIntegerv(GL_MAX_SHADER_STORAGE_BLOCK_SIZE, &max_block_bytes);
  for (size_t bytes : {texels.size(), layers.size()})
    if (bytes > size_t(max_block_bytes))
      return fail(ErrorCode::kUnsupported,
                  fmt::format("GPU compositor: the brush set needs a storage buffer of {} bytes, "
                              "the driver's largest is {}",
                              bytes, max_block_bytes));
  brush_texels = gl::createBuffer();
  layer_bytes = gl::createBuffer();
  mask_tables = gl::createBuffer();
  fill(brush_texels, texels);
  fill(layer_bytes, layers);
  fill(mask_tables, tables);
  setups = gl::createBuffer();
  params = gl::createBuffer();
  layer_taps = gl::createBuffer();
  fill(layer_taps, std::vector<int32_t>{});  // never read without a layer, but bound
  return {};
}

// The layer's bilinear taps per stored column (from the column's level texel) and per row:
// layerTaps depends on X for the columns and on Y for the rows only.
void GpuCompositor::Impl::uploadLayer(const LayerTaps& probe, const TileGeometry& tile,
                                      const ValidRect& rect) {
  const BrushSet::Impl& set = brushes->impl();
  const uint32_t side = tile.sidePx();
  tap_values.assign(size_t(6) * side, 0);
  if (rect.i0 < rect.i1 && rect.j0 < rect.j1) {
    for (uint32_t i = 0; i < side; ++i) {
      const uint32_t ci = std::clamp(i, rect.i0, rect.i1 - 1);
      const uint32_t cj = std::clamp(i, rect.j0, rect.j1 - 1);
      const LayerTaps column = layerTaps(set.height, set.texture_width_px, set.texture_height_px,
                                         tile.level, rect.x0 + ci, rect.y0 + rect.j0);
      const LayerTaps row = layerTaps(set.height, set.texture_width_px, set.texture_height_px,
                                      tile.level, rect.x0 + rect.i0, rect.y0 + cj);
      int32_t* c = &tap_values[size_t(3) * i];
      c[0] = int32_t(column.x0), c[1] = int32_t(column.x1), c[2] = int32_t(column.fx);
      int32_t* r = &tap_values[size_t(3) * (side + i)];
      r[0] = int32_t(row.y0), r[1] = int32_t(row.y1), r[2] = int32_t(row.fy);
    }
  }
  fill(layer_taps, tap_values);
  const GLuint offsets[3] = {0, layer_offsets[0][probe.mip], layer_offsets[1][probe.mip]};
  glProgramUniform1uiv(program.get(), glGetUniformLocation(program.get(), "layer_offsets"), 3,
                       offsets);
  glProgramUniform1i(program.get(), glGetUniformLocation(program.get(), "layer_width"),
                     GLint(set.height.mips[probe.mip].width_px));
}

void GpuCompositor::Impl::draw(const TileGeometry& tile, const ValidRect& rect, size_t instances,
                               Image& out) {
  const uint32_t side = tile.sidePx();
  if (target_side != side) {
    target = gl::createTexture(GL_TEXTURE_2D);
    glTextureStorage2D(target.get(), 1, GL_RGBA8UI, GLsizei(side), GLsizei(side));
    framebuffer = gl::createFramebuffer();
    glNamedFramebufferTexture(framebuffer.get(), GL_COLOR_ATTACHMENT0, target.get(), 0);
    target_side = side;
  }
  fill(setups, setup_values);
  fill(params, param_values);
  const GLuint program_name = program.get();
  glProgramUniform2i(program_name, glGetUniformLocation(program_name, "origin"), GLint(rect.x0),
                     GLint(rect.y0));
  glProgramUniform4i(program_name, glGetUniformLocation(program_name, "valid"), GLint(rect.i0),
                     GLint(rect.i1), GLint(rect.j0), GLint(rect.j1));
  glProgramUniform1i(program_name, glGetUniformLocation(program_name, "instance_count"),
                     GLint(instances));
  glProgramUniform1i(program_name, glGetUniformLocation(program_name, "side"), GLint(side));
  const GLuint buffers[6] = {brush_texels.get(), layer_bytes.get(), mask_tables.get(),
                             setups.get(),       params.get(),      layer_taps.get()};
  glBindBuffersBase(GL_SHADER_STORAGE_BUFFER, 0, 6, buffers);
  glBindFramebuffer(GL_FRAMEBUFFER, framebuffer.get());
  glViewport(0, 0, GLsizei(side), GLsizei(side));
  glDisable(GL_BLEND);
  glDisable(GL_DEPTH_TEST);
  glDisable(GL_SCISSOR_TEST);
  glUseProgram(program_name);
  glBindVertexArray(vertex_array.get());
  glDrawArrays(GL_TRIANGLES, 0, 3);
  // Row j of the tile is framebuffer row j (gl_FragCoord.y), so the read needs no flip.
  out.width_px = side;
  out.height_px = side;
  out.channels = 4;
  out.texels.resize(size_t(side) * side * 4);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, GLsizei(side), GLsizei(side), GL_RGBA_INTEGER, GL_UNSIGNED_BYTE,
               out.texels.data());
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
}

GpuCompositor::GpuCompositor(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
GpuCompositor::~GpuCompositor() = default;

Result<std::unique_ptr<GpuCompositor>> GpuCompositor::create(
    std::shared_ptr<const BrushSet> brushes) {
  TESSERA_CHECK(brushes != nullptr) << "a brush set";
  if (!epoxy_has_gl_extension("GL_ARB_gpu_shader_int64"))
    return fail(ErrorCode::kUnsupported,
                "GPU compositor: the driver lacks GL_ARB_gpu_shader_int64 (64-bit integers in "
                "shaders)");
  auto impl = std::make_unique<Impl>();
  impl->brushes = std::move(brushes);
  const std::string fragment = fmt::format(
      "#version 450 core\n#extension GL_ARB_gpu_shader_int64 : require\n"
      "#define SETUP_INT64S {}\n#define PARAM_INTS {}\n{}",
      gl::kSetupInt64s, gl::kParamInts, gl::kCompositorFragmentShader);
  TESSERA_ASSIGN_OR_RETURN(
      impl->program, gl::linkProgram("GPU compositor", gl::kCompositorVertexShader, fragment));
  impl->vertex_array = gl::createVertexArray();
  TESSERA_TRY(impl->upload());
  return std::unique_ptr<GpuCompositor>(new GpuCompositor(std::move(impl)));
}

const BrushSet& GpuCompositor::brushSet() const {
  return *impl_->brushes;
}

Result<void> GpuCompositor::compositeTile(const TileGeometry& tile,
                                          std::span<const BrushInstance> instances, Image& out,
                                          std::span<const TileClip> clips) {
  TESSERA_CHECK(clips.empty() || clips.size() == instances.size()) << "one clip per instance";
  Impl& impl = *impl_;
  const BrushSet::Impl& set = impl.brushes->impl();
  const ValidRect rect = validRect(tile);
  impl.setup_values.clear();
  impl.param_values.clear();
  for (size_t n = 0; n < instances.size(); ++n) {
    const BrushInstance& instance = instances[n];
    TESSERA_ASSIGN_OR_RETURN(InstanceSetup setup, setupInstance(set, instance, tile.level));
    const InstanceRect r = instanceRect(setup, rect, clips.empty() ? TileClip{} : clips[n]);
    if (r.i_lo >= r.i_hi || r.j_lo >= r.j_hi) continue;  // draws nothing in this tile
    const int64_t setup_values[gl::kSetupInt64s] = {setup.x_c,   setup.y_c,   setup.u_c,
                                                    setup.v_c,   setup.du_dx, setup.du_dy,
                                                    setup.dv_dx, setup.dv_dy};
    impl.setup_values.insert(impl.setup_values.end(), std::begin(setup_values),
                             std::end(setup_values));
    const uint32_t image = instance.variant % uint32_t(setup.brush->images.size());
    const int32_t params[gl::kParamInts] = {
        int32_t(r.i_lo),
        int32_t(r.i_hi),
        int32_t(r.j_lo),
        int32_t(r.j_hi),
        int32_t(setup.tint[0]),
        int32_t(setup.tint[1]),
        int32_t(setup.tint[2]),
        int32_t(setup.tint[3]),
        int32_t(setup.opacity),
        int32_t(setup.brush->blend),
        int32_t(setup.brush->mask),
        int32_t(instance.brush * 256),
        int32_t(impl.mip_offsets[instance.brush][image][setup.mip_index]),
        int32_t(setup.mip->width_px),
        int32_t(setup.mip->height_px),
        0};
    impl.param_values.insert(impl.param_values.end(), std::begin(params), std::end(params));
  }
  if (!set.height.empty())
    impl.uploadLayer(
        layerTaps(set.height, set.texture_width_px, set.texture_height_px, tile.level, 0, 0), tile,
        rect);
  if (rect.i0 == rect.i1 || rect.j0 == rect.j1) {
    // No texel of the tile lies in the level: compositeTile leaves it transparent black.
    out = Image(tile.sidePx(), tile.sidePx(), 4);
    return {};
  }
  while (glGetError() != GL_NO_ERROR) {
  }
  impl.draw(tile, rect, impl.param_values.size() / gl::kParamInts, out);
  if (const GLenum error = glGetError(); error != GL_NO_ERROR)
    return fail(ErrorCode::kInternal,
                fmt::format("GPU compositor: level {} tile {},{}: OpenGL error 0x{:x}", tile.level,
                            tile.x, tile.y, error));
  return {};
}

}  // namespace tessera
