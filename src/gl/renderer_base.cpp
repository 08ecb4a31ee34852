// What both GL renderers share: target, apply bookkeeping, staged uploads, program setup.
#include "renderer_base.h"

#include <algorithm>
#include <string>
#include <vector>

namespace tessera::gl {

namespace {

const char* const kVersionGlsl = "#version 450 core\n";

// The start of every renderer's fragment shader.
const char* const kFragmentPreludeGlsl = R"(#define MAX_LEVELS 32
uniform ivec2 u_level_size[MAX_LEVELS];  // each level's width and height in texels
// The level of detail (Luo & Duan, eq. 2, in OpenGL's form): log2 of the longer screen-axis
// derivative of the level-0 texel coordinate.
float levelOfDetail(vec2 world) {
  return log2(max(length(dFdx(world)), length(dFdy(world))));
}
// The display window (tessera/display_window.h) on a filtered texel, in the units the texture
// returns (u16 as v / 65535): colour = clamp((c - low) * scale, 0, 1) ^ gamma. A NaN sample
// anywhere in the filter's footprint is no data.
uniform float u_window_low;
uniform float u_window_scale;
uniform float u_window_gamma;
uniform bool u_alpha_clamp;  // float alpha: clamped to [0, 1]
vec4 displayColour(vec4 texel) {
  if (any(isnan(texel))) return vec4(0.0);
  vec3 colour = clamp((texel.rgb - u_window_low) * u_window_scale, 0.0, 1.0);
  if (u_window_gamma != 1.0) colour = pow(colour, vec3(u_window_gamma));
  return vec4(colour, u_alpha_clamp ? clamp(texel.a, 0.0, 1.0) : texel.a);
}
)";

static_assert(kMaxShaderLevels == 32, "MAX_LEVELS in kFragmentPreludeGlsl");

}  // namespace

RendererBase::RendererBase(const ImageInfo& info, const RendererOptions& options)
    : info_(info),
      options_(options),
      texel_format_(tileTexelFormat(info.channels, info.sample_type)),
      window_(fullRangeWindow(info.sample_type)) {
  // Here, not at the first upload: mapping the ring (tens of MiB the driver may clear) would
  // otherwise fall inside the first frame of a flight.
  staging_.emplace(options_.staging_ring_bytes);
  if (options_.staging_ring_bytes > 0) ++stats_.storage_allocations;
}

void RendererBase::setDisplayWindow(const DisplayWindow& window) {
  // The viewer sets it every frame: unchanged, it costs no GL call.
  const bool unchanged =
      window.low == window_.low && window.high == window_.high && window.gamma == window_.gamma;
  window_ = window;
  if (unchanged) return;
  for (GLuint program : window_programs_) uploadWindow(program);
}

void RendererBase::uploadWindow(GLuint p) const {
  // The texture returns u8 and u16 samples divided by their largest value; f32 as stored.
  const double unit = info_.sample_type == SampleType::kU16  ? 65535.0
                      : info_.sample_type == SampleType::kU8 ? 255.0
                                                             : 1.0;
  glProgramUniform1f(p, glGetUniformLocation(p, "u_window_low"), float(window_.low / unit));
  glProgramUniform1f(p, glGetUniformLocation(p, "u_window_scale"),
                     float(unit / (window_.high - window_.low)));
  glProgramUniform1f(p, glGetUniformLocation(p, "u_window_gamma"), float(window_.gamma));
  glProgramUniform1i(p, glGetUniformLocation(p, "u_alpha_clamp"),
                     info_.sample_type == SampleType::kF32 ? 1 : 0);
}

Picture RendererBase::readPixels() {
  Picture picture;
  picture.width = target_.width();
  picture.height = target_.height();
  target_.read(picture.rgba);
  return picture;
}

void RendererBase::present(uint32_t window_width, uint32_t window_height) {
  target_.blitToWindow(window_width, window_height);
}

Result<void> RendererBase::linkRendererProgram(const char* name, const char* vertex_body,
                                               const char* fragment_body) {
  Result<Program> program =
      linkProgram(name, std::string(kVersionGlsl) + vertex_body,
                  std::string(kVersionGlsl) + kFragmentPreludeGlsl + fragment_body);
  if (!program) return forwardError(program);
  program_ = std::move(*program);
  const GLuint p = program_.get();
  view_projection_uniform_ = glGetUniformLocation(p, "u_view_projection");
  std::vector<GLint> sizes;
  for (uint32_t level = 0; level < std::min(info_.level_count, kMaxShaderLevels); ++level) {
    sizes.push_back(GLint(info_.levelWidthPx(level)));
    sizes.push_back(GLint(info_.levelHeightPx(level)));
  }
  glProgramUniform2iv(p, glGetUniformLocation(p, "u_level_size"), GLsizei(sizes.size() / 2),
                      sizes.data());
  // A renderer may keep several programs (moving program_ aside before linking the next):
  // each gets the window now and at every change.
  window_programs_.push_back(p);
  uploadWindow(p);
  return {};
}

void RendererBase::beginApply() {
  result_.accepted.clear();
  result_.declined.clear();
  result_.dropped.clear();
  result_.upload_ms = 0;
  stats_.uploads = 0;
  stats_.upload_bytes = 0;
  stats_.declined = 0;
}

bool RendererBase::holds(const DecodedTile& tile) const {
  if (tile.keptAsBlocks())
    return block_codec_ != Codec::kRaw && tile.blocks.codec == block_codec_ &&
           tile.blocks.padded_side_px == blockSidePx() && tile.id.level < info_.level_count;
  return tile.texels.channels == info_.channels && tile.texels.sample_type == info_.sample_type &&
         tile.texels.width_px == info_.storedTileSidePx() &&
         tile.texels.height_px == info_.storedTileSidePx() && tile.id.level < info_.level_count;
}

void RendererBase::decline(const TileId& id) {
  result_.declined.push_back(id);
  ++stats_.declined;
}

void RendererBase::drop(const TileId& id) {
  result_.dropped.push_back(id);
}

void RendererBase::uploadStaged(
    std::span<const PendingUpload> pending,
    const std::function<void(const DecodedTile&, uint32_t, size_t)>& write) {
  if (pending.empty()) return;
  const auto started = Clock::now();
  sources_.clear();
  for (const PendingUpload& p : pending)
    if (p.tile) sources_.emplace_back(p.tile->uploadBytes().data(), p.tile->uploadBytes().size());
  size_t offset = staging_->stage(sources_);  // staged one after the other, in this order
  for (const PendingUpload& p : pending) {
    if (!p.tile) continue;
    write(*p.tile, p.place, offset);
    offset += p.tile->uploadBytes().size();
    result_.accepted.push_back(p.tile->id);
    ++stats_.uploads;
    stats_.upload_bytes += p.tile->uploadBytes().size();
  }
  staging_->finish();
  // What the adaptive upload budget is fed (TileStreamer::acknowledge): the render thread's
  // time for this frame's copies and texture updates.
  result_.upload_ms = msSince(started);
}

size_t RendererBase::stagingRoom() {
  return staging_->room();
}

const ApplyResult& RendererBase::endApply(Clock::time_point started, size_t resident_tiles) {
  stats_.resident_tiles = uint32_t(resident_tiles);
  stats_.apply_cpu_ms = msSince(started);
  return result_;
}

ViewProjection RendererBase::beginDraw(const View& view) {
  if (target_.width() != view.viewportWidth() || target_.height() != view.viewportHeight())
    ++stats_.storage_allocations;  // bind() makes a target of the new size
  target_.bind(view.viewportWidth(), view.viewportHeight());
  glClearColor(0, 0, 0, 0);
  glClear(GL_COLOR_BUFFER_BIT);
  glDisable(GL_DEPTH_TEST);
  glDisable(GL_BLEND);
  const ViewProjection projection = viewProjection(view, info_);
  glProgramUniformMatrix4fv(program_.get(), view_projection_uniform_, 1, GL_FALSE,
                            projection.matrix);
  return projection;
}

double RendererBase::msSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

}  // namespace tessera::gl
