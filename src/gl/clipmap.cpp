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
#include <string>
#include <unordered_map>
#include <vector>

#include <fmt/format.h>

#include "renderer_base.h"
#include "renderers.h"
#include "stream/footprint.h"

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
out vec4 o_colour;
#if HELD_VIEW
// An orthographic view whose footprint is held at the level it wants (and at the next
// coarser one where it blends): one level of detail everywhere, chosen on the CPU, and no
// owner checks. The layer wraps (GL_REPEAT), so the hardware's bilinear fetch reads the
// toroidal neighbours; clamping the coordinate to half a texel inside the level's image is
// the clamp of the texel indices. Coordinates are in layer widths (texels / N), from one
// multiply-add per fragment: a software rasteriser pays for every operation. Index 0: the
// wanted level, 1: the next coarser.
uniform float u_held_scale[2];   // 2^-level / N
uniform vec2 u_held_offset[2];   // where the anchor lies in the layer, / N
uniform vec4 u_held_bounds[2];   // the texel centres of the image's edges, same units
uniform float u_held_layer[2];
uniform float u_held_weight;     // lambda - level: the coarser level's share
vec4 heldBilinear(int k) {
  vec2 at = clamp(v_world * u_held_scale[k] + u_held_offset[k], u_held_bounds[k].xy,
                  u_held_bounds[k].zw);
  return textureLod(u_texels, vec3(at, u_held_layer[k]), 0.0);
}
void main() {
#if HELD_VIEW == 1
  o_colour = displayColour(heldBilinear(0));  // the view sits on a level: lambda - level is 0
#else
  o_colour = displayColour(mix(heldBilinear(0), heldBilinear(1), u_held_weight));
#endif
}
#else
uniform usampler2DArray u_owner;   // layer = level, n x n slots: owning tile + 1, 0 = empty
uniform ivec2 u_anchor_int[MAX_LEVELS];   // the anchor in level texels, integer part
uniform vec2 u_anchor_frac[MAX_LEVELS];   // and fraction
uniform int u_coarsest;
uniform int u_tile;    // t
uniform int u_slots;   // n

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
#endif
)";

class ClipmapRenderer final : public RendererBase {
 public:
  ClipmapRenderer(const ImageInfo& info, const RendererOptions& options)
      : RendererBase(info, options) {}

  Result<void> init() {
    if (info_.level_count > kMaxShaderLevels)
      return fail(ErrorCode::kUnsupported, fmt::format("clipmap renderer: {} levels, at most {}",
                                                       info_.level_count, kMaxShaderLevels));
    // Three programs: a software rasteriser runs both sides of a branch on every fragment, so
    // the owner-checked filtering would cost a held view's frames as much as before. The
    // held ones (one fetch on a level, two between levels) are linked first: the base class
    // keeps u_view_projection of the last.
    for (int variant : {1, 2}) {
      TESSERA_TRY(linkRendererProgram(
          "clipmap (held view)", kVertexShader,
          (fmt::format("#define HELD_VIEW {}\n", variant) + kFragmentShader).c_str()));
      held_[variant - 1] = heldProgram(std::move(program_));
    }
    TESSERA_TRY(
        linkRendererProgram("clipmap", kVertexShader,
                            (std::string("#define HELD_VIEW 0\n") + kFragmentShader).c_str()));
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
    if (options_.initial_clip_tiles > 0) reallocate(options_.initial_clip_tiles);
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
    const HeldProgram* held =
        view.kind == View::Kind::kOrtho ? setHeldUniforms(view, transform) : nullptr;
    const GLuint p = held ? held->program.get() : program_.get();
    glProgramUniform4f(p, held ? held->rect : rect_uniform_, float(-transform.anchor_x),
                       float(-transform.anchor_y), float(info_.width_px - transform.anchor_x),
                       float(info_.height_px - transform.anchor_y));
    stats_.tiles_drawn = uint32_t(slot_of_.size());
    if (!held) setOwnerCheckedUniforms(transform);
    glUseProgram(p);
    glBindTextureUnit(0, texels_.get());
    glBindTextureUnit(1, owner_.get());
    glBindVertexArray(vertex_array_.get());
    glDrawArrays(GL_TRIANGLE_STRIP, 0, 4);
    glBindVertexArray(0);
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
  /// The per-level uniforms of the owner-checked program: the anchor in each level's texels.
  void setOwnerCheckedUniforms(const ViewProjection& transform) {
    const GLuint p = program_.get();
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
  }

  /// A held-view program and its uniform locations (-1 where a variant lacks one).
  struct HeldProgram {
    Program program;
    GLint view_projection = -1, rect = -1, scale = -1, offset = -1, bounds = -1, layer = -1,
          weight = -1;
  };

  static HeldProgram heldProgram(Program program) {
    HeldProgram held;
    const GLuint p = program.get();
    glProgramUniform1i(p, glGetUniformLocation(p, "u_texels"), 0);
    held.view_projection = glGetUniformLocation(p, "u_view_projection");
    held.rect = glGetUniformLocation(p, "u_rect");
    held.scale = glGetUniformLocation(p, "u_held_scale");
    held.offset = glGetUniformLocation(p, "u_held_offset");
    held.bounds = glGetUniformLocation(p, "u_held_bounds");
    held.layer = glGetUniformLocation(p, "u_held_layer");
    held.weight = glGetUniformLocation(p, "u_held_weight");
    held.program = std::move(program);
    return held;
  }

  /// For an orthographic view: when every tile its footprint (widened by a texel for the
  /// bilinear footprints at its edges) meets is held at the level the view wants, and at the
  /// next coarser level where it blends with it, sets the uniforms of the held program that
  /// draws it and returns that program; null otherwise. The picture is then what the owner-checked
  /// program draws: that program falls back to a coarser level only where a texel is not held.
  const HeldProgram* setHeldUniforms(const View& view, const ViewProjection& transform) {
    const double texels_per_pixel = texelsPerPixelOf(view.ortho);
    const uint32_t level = desiredLevelFor(texels_per_pixel, info_.level_count);
    const bool coarsest = level + 1 >= info_.level_count;
    const double weight =
        coarsest ? 0.0 : std::clamp(std::log2(texels_per_pixel) - double(level), 0.0, 1.0);
    const tessera::detail::Footprint footprint = tessera::detail::footprintOf(view, info_);
    if (!footprintHeld(footprint, view.image, level) ||
        (weight > 0 && !footprintHeld(footprint, view.image, level + 1)))
      return nullptr;
    const double side = double(slots_) * info_.tile_size_px;
    GLfloat scale[2], offset[4], bounds[8], layer[2];
    for (uint32_t k = 0; k < 2; ++k) {
      const uint32_t at = std::min(level + k, info_.level_count - 1);
      const double size[2] = {double(info_.levelWidthPx(at)), double(info_.levelHeightPx(at))};
      const double anchor[2] = {transform.anchor_x, transform.anchor_y};
      for (int axis = 0; axis < 2; ++axis) {
        const double scaled = std::ldexp(anchor[axis], -int(at));
        // The anchor's place on the torus, kept small: the coordinates stay exact on images
        // of any size.
        const double torus = scaled - side * std::floor(scaled / side);
        offset[k * 2 + axis] = GLfloat(torus / side);
        bounds[k * 4 + axis] = GLfloat((torus - scaled + 0.5) / side);
        bounds[k * 4 + 2 + axis] = GLfloat((torus - scaled + size[axis] - 0.5) / side);
      }
      scale[k] = GLfloat(std::ldexp(1.0, -int(at)) / side);
      layer[k] = GLfloat(at);
    }
    const HeldProgram& held = held_[weight > 0 ? 1 : 0];
    const GLuint p = held.program.get();
    glProgramUniformMatrix4fv(p, held.view_projection, 1, GL_FALSE, transform.matrix);
    glProgramUniform1fv(p, held.scale, 2, scale);
    glProgramUniform2fv(p, held.offset, 2, offset);
    glProgramUniform4fv(p, held.bounds, 2, bounds);
    glProgramUniform1fv(p, held.layer, 2, layer);
    glProgramUniform1f(p, held.weight, GLfloat(weight));
    return &held;
  }

  /// True when every tile of `level` that the footprint, widened by one texel of that level
  /// on each side, meets is held; false also when they are more than a layer holds.
  bool footprintHeld(const tessera::detail::Footprint& footprint, uint32_t image,
                     uint32_t level) const {
    const double texel = std::ldexp(1.0, int(level));
    const double span = texel * info_.tile_size_px;
    const double x0 = std::max(footprint.x0 - texel, 0.0);
    const double y0 = std::max(footprint.y0 - texel, 0.0);
    const double x1 = std::min(footprint.x1 + texel, double(info_.width_px));
    const double y1 = std::min(footprint.y1 + texel, double(info_.height_px));
    if (!(x1 > x0 && y1 > y0)) return false;
    const uint32_t tx0 = uint32_t(x0 / span), ty0 = uint32_t(y0 / span);
    const uint32_t tx1 = std::min(uint32_t(std::ceil(x1 / span)), info_.tilesX(level));
    const uint32_t ty1 = std::min(uint32_t(std::ceil(y1 / span)), info_.tilesY(level));
    if (tx1 - tx0 > slots_ || ty1 - ty0 > slots_) return false;
    for (uint32_t y = ty0; y < ty1; ++y)
      for (uint32_t x = tx0; x < tx1; ++x)
        if (!slot_of_.count({image, level, x, y})) return false;
    return true;
  }

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
    ++stats_.storage_allocations;
    const GLsizei side = GLsizei(slots_ * info_.tile_size_px);
    const GLsizei levels = GLsizei(info_.level_count);
    texels_ = createTileArray(info_.channels, info_.sample_type, side, levels);
    // The held-view program's bilinear fetches wrap around the torus.
    glTextureParameteri(texels_.get(), GL_TEXTURE_WRAP_S, GL_REPEAT);
    glTextureParameteri(texels_.get(), GL_TEXTURE_WRAP_T, GL_REPEAT);
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

  HeldProgram held_[2];  ///< on a level; blending with the next coarser
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
