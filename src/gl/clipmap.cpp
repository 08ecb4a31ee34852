// The clipmap renderer (Luo & Duan, sections 3.3 and 3.5): one texture-array layer per level,
// n x n tiles of it, addressed toroidally (tile (x, y) lives in slot (x mod n, y mod n)), so a
// moving clip region uploads only the tiles that entered it and nothing is ever copied. Each
// fragment picks its level from screen-space derivatives (their eq. 2 in OpenGL's form), falls
// back to the finest level that holds every texel its bilinear footprint needs, and so never
// samples across the toroidal seam (their one-texel shrink, done per fragment: a footprint
// that reaches a slot holding another tile, or none, moves to the next coarser level).
#include <algorithm>
#include <cmath>
#include <optional>
#include <unordered_map>
#include <vector>

#include <fmt/format.h>

#include "renderer_base.h"
#include "renderers.h"

namespace tessera::gl {

namespace {

const char* const kVertexShader = R"(
uniform vec4 u_rect;  // the image, level-0 texels relative to the anchor
uniform mat4 u_view_projection;
out vec2 v_world;
void main() {
  vec2 corner = vec2(gl_VertexID & 1, gl_VertexID >> 1);
  v_world = mix(u_rect.xy, u_rect.zw, corner);
  gl_Position = u_view_projection * vec4(v_world, 0.0, 1.0);
}
)";

const char* const kFragmentShader = R"(
in vec2 v_world;
uniform sampler2DArray u_texels;   // layer = level, N x N texels, toroidal
uniform usampler2DArray u_owner;   // layer = level, n x n slots: owning tile + 1, 0 = empty
uniform ivec2 u_anchor_int[MAX_LEVELS];   // the anchor in level texels, integer part
uniform vec2 u_anchor_frac[MAX_LEVELS];   // and fraction
uniform int u_coarsest;
uniform int u_tile;    // t
uniform int u_slots;   // n
out vec4 o_colour;

bool heldAt(int level, ivec2 texel) {
  ivec2 tile = texel / u_tile;
  uvec2 owner = texelFetch(u_owner, ivec3(tile % u_slots, level), 0).rg;
  return owner == uvec2(tile + 1);
}

vec4 texelAt(int level, ivec2 texel) {
  return texelFetch(u_texels, ivec3(texel % (u_tile * u_slots), level), 0);
}

// Bilinear at `level`, texel indices clamped to the level's image as stored borders and
// padding replicate it; false when a texel of the footprint is not held.
bool bilinear(int level, vec2 world, out vec4 colour) {
  vec2 local = u_anchor_frac[level] + world * exp2(-float(level)) - 0.5;
  vec2 base = floor(local);
  vec2 f = local - base;
  ivec2 last = u_level_size[level] - 1;
  ivec2 t0 = clamp(u_anchor_int[level] + ivec2(base), ivec2(0), last);
  ivec2 t1 = clamp(u_anchor_int[level] + ivec2(base) + 1, ivec2(0), last);
  if (!heldAt(level, t0) || !heldAt(level, ivec2(t1.x, t0.y)) || !heldAt(level, ivec2(t0.x, t1.y)) ||
      !heldAt(level, t1))
    return false;
  vec4 top = mix(texelAt(level, t0), texelAt(level, ivec2(t1.x, t0.y)), f.x);
  vec4 bottom = mix(texelAt(level, ivec2(t0.x, t1.y)), texelAt(level, t1), f.x);
  colour = mix(top, bottom, f.y);
  return true;
}

void main() {
  float lambda = levelOfDetail(v_world);
  int wanted = clamp(int(floor(lambda)), 0, u_coarsest);
  for (int level = wanted; level <= u_coarsest; ++level) {
    vec4 colour;
    if (!bilinear(level, v_world, colour)) continue;
    if (level == wanted && level < u_coarsest && lambda > float(level)) {
      vec4 coarser;
      if (bilinear(level + 1, v_world, coarser))
        colour = mix(colour, coarser, clamp(lambda - float(level), 0.0, 1.0));
    }
    o_colour = displayColour(colour);
    return;
  }
  o_colour = vec4(0.0);
}
)";

class ClipmapRenderer final : public RendererBase {
 public:
  ClipmapRenderer(const ImageInfo& info, const RendererOptions& options)
      : RendererBase(info, options) {}

  Result<void> init() {
    if (info_.level_count > kMaxShaderLevels)
      return fail(ErrorCode::kUnsupported, fmt::format("clipmap renderer: {} levels, at most {}",
                                                       info_.level_count, kMaxShaderLevels));
    TESSERA_TRY(linkRendererProgram("clipmap", kVertexShader, kFragmentShader));
    const GLuint p = program_.get();
    glProgramUniform1i(p, glGetUniformLocation(p, "u_texels"), 0);
    glProgramUniform1i(p, glGetUniformLocation(p, "u_owner"), 1);
    glProgramUniform1i(p, glGetUniformLocation(p, "u_coarsest"), GLint(info_.level_count - 1));
    glProgramUniform1i(p, glGetUniformLocation(p, "u_tile"), GLint(info_.tile_size_px));
    rect_uniform_ = glGetUniformLocation(p, "u_rect");
    anchor_int_uniform_ = glGetUniformLocation(p, "u_anchor_int");
    anchor_frac_uniform_ = glGetUniformLocation(p, "u_anchor_frac");
    slots_uniform_ = glGetUniformLocation(p, "u_slots");
    vertex_array_ = createVertexArray();
    return {};
  }

  const ApplyResult& apply(const FrameUpdate& update) override {
    const auto started = Clock::now();
    beginApply();
    // The layers hold n x n tiles, n the clip region's side (eq. 3): a larger one (a bigger
    // window) reallocates them and drops every tile, to be uploaded again.
    const uint32_t needed =
        std::max({options_.initial_clip_tiles, update.clip_region_tiles, uint32_t(1)});
    if (needed > slots_) reallocate(needed);
    regions_.assign(info_.level_count, TileRect{});
    for (const auto& region : update.regions)
      if (region.level < info_.level_count) regions_[region.level] = region.region;
    for (const TileId& id : update.releases) {
      auto it = slot_of_.find(id);
      if (it == slot_of_.end()) continue;
      setOwner(id.level, it->second, nullptr);
      slot_of_.erase(it);
    }
    placeUploads(update);
    if (!pending_.empty()) uploadInteriors();
    return endApply(started, slot_of_.size());
  }

  void draw(const View& view) override {
    const auto started = Clock::now();
    const ViewProjection transform = beginDraw(view);
    stats_.tiles_drawn = 0;
    if (slots_ == 0) {
      stats_.draw_cpu_ms = 0;
      return;
    }
    const GLuint p = program_.get();
    glProgramUniform4f(p, rect_uniform_, float(-transform.anchor_x), float(-transform.anchor_y),
                       float(info_.width_px - transform.anchor_x),
                       float(info_.height_px - transform.anchor_y));
    glProgramUniform1i(p, slots_uniform_, GLint(slots_));
    // The anchor in each level's texels, split so the shader adds small floats to exact
    // integers: texel addresses stay exact on images of any size.
    std::vector<GLint> anchor_int;
    std::vector<GLfloat> anchor_frac;
    for (uint32_t level = 0; level < info_.level_count; ++level) {
      for (double a : {transform.anchor_x, transform.anchor_y}) {
        const double scaled = std::ldexp(a, -int(level));
        const double whole = std::floor(scaled);
        anchor_int.push_back(GLint(whole));
        anchor_frac.push_back(GLfloat(scaled - whole));
      }
    }
    glProgramUniform2iv(p, anchor_int_uniform_, GLsizei(info_.level_count), anchor_int.data());
    glProgramUniform2fv(p, anchor_frac_uniform_, GLsizei(info_.level_count), anchor_frac.data());
    glUseProgram(p);
    glBindTextureUnit(0, texels_.get());
    glBindTextureUnit(1, owner_.get());
    glBindVertexArray(vertex_array_.get());
    glDrawArrays(GL_TRIANGLE_STRIP, 0, 4);
    glBindVertexArray(0);
    stats_.tiles_drawn = uint32_t(slot_of_.size());
    stats_.draw_cpu_ms = msSince(started);
  }

  bool resident(const TileId& tile) const override { return slot_of_.count(tile) > 0; }
  RendererKind kind() const override { return RendererKind::kClipmap; }

  Result<ClipmapLayer> readLayer(uint32_t level) const {
    if (level >= info_.level_count || slots_ == 0)
      return fail(ErrorCode::kInvalidArgument, fmt::format("clipmap has no layer {}", level));
    ClipmapLayer layer;
    layer.slots = slots_;
    layer.side = slots_ * info_.tile_size_px;
    layer.texels.resize(size_t(layer.side) * layer.side * info_.texelBytes());
    layer.owners = owners_[level];
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glGetTextureSubImage(texels_.get(), 0, 0, 0, GLint(level), GLsizei(layer.side),
                         GLsizei(layer.side), 1, texel_format_.pixel_format,
                         texel_format_.pixel_type, GLsizei(layer.texels.size()),
                         layer.texels.data());
    return layer;
  }

 private:
  uint32_t slotOf(const TileId& id) const { return (id.y % slots_) * slots_ + (id.x % slots_); }

  bool inRegion(const TileId& id) const {
    return id.level < regions_.size() && regions_[id.level].contains(id.x, id.y);
  }

  void setOwner(uint32_t level, uint32_t slot, const TileId* id) {
    owners_[level][slot] = id ? std::optional<TileId>(*id) : std::nullopt;
    const GLuint value[2] = {id ? id->x + 1 : 0, id ? id->y + 1 : 0};
    glTextureSubImage3D(owner_.get(), 0, GLint(slot % slots_), GLint(slot / slots_), GLint(level),
                        1, 1, 1, GL_RG_INTEGER, GL_UNSIGNED_INT, value);
  }

  /// Gives each of this frame's uploads its slot (pending_), or declines it.
  void placeUploads(const FrameUpdate& update) {
    pending_.clear();
    pending_index_.clear();
    size_t room = stagingRoom();
    for (const auto& tile : update.uploads) {
      const TileId& id = tile->id;
      // Not this image's, or no room left in the staging ring this frame (offered again).
      if (!holds(*tile) || tile->texels.texels.size() > room) {
        decline(id);
        continue;
      }
      const uint32_t slot = slotOf(id);
      const std::optional<TileId>& owner = owners_[id.level][slot];
      if (owner && *owner != id) {
        // Two tiles of a level share a slot only when one lies outside the clip region (the
        // keep margin, the lookahead, far ground in perspective): a tile inside takes the slot,
        // one outside never evicts another (two outside tiles would take it in turns, each
        // sent back to be loaded and offered again).
        if (!inRegion(id)) {
          decline(id);
          continue;
        }
        // A tile that took the slot earlier in this same frame never went up: it is declined,
        // not dropped.
        auto earlier = pending_index_.find(*owner);
        if (earlier != pending_index_.end()) {
          pending_[earlier->second].tile = nullptr;
          decline(*owner);
          pending_index_.erase(earlier);
        } else {
          drop(*owner);
        }
        slot_of_.erase(*owner);
      }
      setOwner(id.level, slot, &id);
      slot_of_[id] = slot;
      pending_index_[id] = pending_.size();
      pending_.push_back({tile.get(), slot});
      room -= tile->texels.texels.size();
    }
  }

  /// Uploads the interior of each pending tile into its slot: its borders are its
  /// neighbours' texels, which sit beside it in the layer already.
  void uploadInteriors() {
    glPixelStorei(GL_UNPACK_ROW_LENGTH, GLint(info_.storedTileSidePx()));
    glPixelStorei(GL_UNPACK_SKIP_PIXELS, GLint(info_.border_px));
    glPixelStorei(GL_UNPACK_SKIP_ROWS, GLint(info_.border_px));
    const GLsizei t = GLsizei(info_.tile_size_px);
    uploadStaged(pending_, [&](const DecodedTile& tile, uint32_t slot, size_t offset) {
      const GLint sx = GLint(slot % slots_) * t, sy = GLint(slot / slots_) * t;
      glTextureSubImage3D(texels_.get(), 0, sx, sy, GLint(tile.id.level), t, t, 1,
                          texel_format_.pixel_format, texel_format_.pixel_type,
                          reinterpret_cast<const void*>(offset));
    });
    glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
    glPixelStorei(GL_UNPACK_SKIP_PIXELS, 0);
    glPixelStorei(GL_UNPACK_SKIP_ROWS, 0);
  }

  /// Layers of `slots` x `slots` tiles; every tile held so far is dropped.
  void reallocate(uint32_t slots) {
    for (const auto& [id, slot] : slot_of_) drop(id);
    slot_of_.clear();
    slots_ = slots;
    const GLsizei side = GLsizei(slots_ * info_.tile_size_px);
    const GLsizei levels = GLsizei(info_.level_count);
    texels_ = createTileArray(info_.channels, info_.sample_type, side, levels);
    owner_ = createTexture(GL_TEXTURE_2D_ARRAY);
    glTextureStorage3D(owner_.get(), 1, GL_RG32UI, GLsizei(slots_), GLsizei(slots_), levels);
    // An integer texture with a linear filter is incomplete, and fetches from it return 0.
    glTextureParameteri(owner_.get(), GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTextureParameteri(owner_.get(), GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    const std::vector<GLuint> zeros(size_t(slots_) * slots_ * 2 * info_.level_count, 0);
    glTextureSubImage3D(owner_.get(), 0, 0, 0, 0, GLsizei(slots_), GLsizei(slots_), levels,
                        GL_RG_INTEGER, GL_UNSIGNED_INT, zeros.data());
    owners_.assign(info_.level_count, std::vector<std::optional<TileId>>(size_t(slots_) * slots_));
    stats_.gpu_bytes = uint64_t(side) * side * levels * info_.texelBytes();
  }

  GLint rect_uniform_ = -1, anchor_int_uniform_ = -1, anchor_frac_uniform_ = -1,
        slots_uniform_ = -1;
  Texture texels_, owner_;
  uint32_t slots_ = 0;                                      ///< n: tiles along a layer's side
  std::vector<std::vector<std::optional<TileId>>> owners_;  ///< per level, per slot
  std::unordered_map<TileId, uint32_t, TileIdHash> slot_of_;
  std::vector<TileRect> regions_;       ///< this frame's clip region per level
  std::vector<PendingUpload> pending_;  ///< scratch of apply: this frame's uploads, in order
  std::unordered_map<TileId, size_t, TileIdHash> pending_index_;  ///< into pending_
};

}  // namespace

Result<ClipmapLayer> readClipmapLayer(Renderer& renderer, uint32_t level) {
  auto* clipmap = dynamic_cast<ClipmapRenderer*>(&renderer);
  if (!clipmap) return fail(ErrorCode::kInvalidArgument, "not a clipmap renderer");
  return clipmap->readLayer(level);
}

Result<std::unique_ptr<Renderer>> createClipmapRenderer(const ImageInfo& info,
                                                        const RendererOptions& options) {
  auto renderer = std::make_unique<ClipmapRenderer>(info, options);
  TESSERA_TRY(renderer->init());
  return std::unique_ptr<Renderer>(std::move(renderer));
}

}  // namespace tessera::gl
