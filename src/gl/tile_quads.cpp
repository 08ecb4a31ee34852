// The tile-quads renderer (Backes et al., section 7): one quad per resident tile that meets
// the view, coarse levels first and finer ones over them, tiles in one texture array. Each
// fragment applies the sampling rules of tessera/render.h: a tile draws where the level of
// detail lambda is below its level + 1, blending with its parent (also resident: the streamer
// uploads parents first and releases them last) for trilinear filtering; where a finer tile
// is missing, the coarser one beneath shows through, magnified.
#include <algorithm>
#include <cmath>
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
// Per tile: its rectangle in level-0 texels relative to the view's anchor, clipped to the
// image; the tile's and its parent's origins (level-0 texels, same anchor); level, layer,
// parent layer (-1: none) and whether it is the coarsest level.
layout(location = 0) in vec4 a_rect;
layout(location = 1) in vec4 a_origins;
layout(location = 2) in ivec4 a_info;
layout(location = 3) in ivec2 a_tile;  // the tile's (x, y) at its level
uniform mat4 u_view_projection;
out vec2 v_world;
flat out vec4 v_origins;
flat out ivec4 v_info;
flat out ivec2 v_tile;
flat out int v_instance;
void main() {
  vec2 corner = vec2(gl_VertexID & 1, gl_VertexID >> 1);
  v_world = mix(a_rect.xy, a_rect.zw, corner);
  v_origins = a_origins;
  v_info = a_info;
  v_tile = a_tile;
  v_instance = gl_InstanceID;
  gl_Position = u_view_projection * vec4(v_world, 0.0, 1.0);
}
)";

const char* const kFragmentShader = R"(
in vec2 v_world;
flat in vec4 v_origins;
flat in ivec4 v_info;
flat in ivec2 v_tile;
flat in int v_instance;
uniform sampler2DArray u_tiles;
uniform float u_tile_size;
uniform float u_border;
uniform float u_stored_side;
out vec4 o_colour;
#if BLOCKS
// bc1/bc7 tiles as stored, in layers padded to whole 4x4 blocks (u_block_side): the padding
// lies past the stored tile's right and bottom edges, so a texel keeps its coordinate and only
// the normalisation changes. Layers from TEXEL_LAYER on are decoded tiles (uniform tiles have
// no blocks) in u_tiles. Level 0 only, so explicit-LOD sampling in this branch is exact.
uniform sampler2DArray u_blocks;
uniform float u_block_side;
vec4 tileTexture(vec2 texel, int layer) {
  if (layer >= TEXEL_LAYER)
    return textureLod(u_tiles, vec3(texel / u_stored_side, float(layer - TEXEL_LAYER)), 0.0);
  return textureLod(u_blocks, vec3(texel / u_block_side, float(layer)), 0.0);
}
vec4 tileTexel(ivec2 texel, int layer) {
  if (layer >= TEXEL_LAYER) return texelFetch(u_tiles, ivec3(texel, layer - TEXEL_LAYER), 0);
  return texelFetch(u_blocks, ivec3(texel, layer), 0);
}
#else
vec4 tileTexture(vec2 texel, int layer) {
  return texture(u_tiles, vec3(texel / u_stored_side, float(layer)));
}
vec4 tileTexel(ivec2 texel, int layer) { return texelFetch(u_tiles, ivec3(texel, layer), 0); }
#endif
// Bilinear at `level` inside one stored tile; its border holds the neighbours' texels, so the
// four texels around any point of the tile are in it.
vec4 sampleTile(vec2 world, vec2 origin, int level, int layer) {
  vec2 texel = (world - origin) * exp2(-float(level)) + u_border;
  return tileTexture(texel, layer);
}
#if BORDERLESS
// Without borders: per instance, the layers of the 3 x 3 tiles around the tile, then around
// its parent (-1 where not resident).
layout(std430, binding = 0) readonly buffer Neighbours { int neighbours[]; };
// Tiles stored without borders: the four texels come from whichever of the 3 x 3 tiles
// around `tile` holds them, indices clamped to the level's image as the reference clamps
// them. A neighbour that is not resident lends nothing: its texel is taken from the nearest
// texel of this tile instead.
vec4 sampleBorderless(vec2 world, vec2 origin, int level, ivec2 tile, int table) {
  int t = int(u_tile_size);
  vec2 local = (world - origin) * exp2(-float(level)) - 0.5;
  vec2 base = floor(local);
  vec2 f = local - base;
  ivec2 last = u_level_size[level] - 1;
  vec4 texels[4];
  for (int k = 0; k < 4; ++k) {
    ivec2 global = clamp(tile * t + ivec2(base) + ivec2(k & 1, k >> 1), ivec2(0), last);
    ivec2 d = clamp(global / t - tile, ivec2(-1), ivec2(1));
    int layer = neighbours[v_instance * 18 + table + (d.y + 1) * 3 + (d.x + 1)];
    if (layer < 0) {
      d = ivec2(0);
      layer = neighbours[v_instance * 18 + table + 4];
      global = clamp(global, tile * t, tile * t + t - 1);
    }
    texels[k] = tileTexel(global - (tile + d) * t, layer);
  }
  return mix(mix(texels[0], texels[1], f.x), mix(texels[2], texels[3], f.x), f.y);
}
#endif
#if BORDERLESS
vec4 own() { return sampleBorderless(v_world, v_origins.xy, v_info.x, v_tile, 0); }
vec4 parent() { return sampleBorderless(v_world, v_origins.zw, v_info.x + 1, v_tile / 2, 9); }
#else
vec4 own() { return sampleTile(v_world, v_origins.xy, v_info.x, v_info.y); }
vec4 parent() { return sampleTile(v_world, v_origins.zw, v_info.x + 1, v_info.z); }
#endif
#if ORTHO_LOD == 0
// The level of detail per fragment (perspective views).
void main() {
  float lambda = levelOfDetail(v_world);
  int level = v_info.x;
  bool coarsest = v_info.w != 0;
  if (!coarsest && lambda >= float(level + 1)) discard;  // a coarser tile beneath draws here
  vec4 colour = own();
  if (lambda > float(level) && v_info.z >= 0)
    colour = mix(colour, parent(), clamp(lambda - float(level), 0.0, 1.0));
  o_colour = displayColour(colour);
}
#else
// An orthographic view: one level of detail for the whole view (u_lambda, from the CPU),
// which drew no tile finer than its level. ORTHO_LOD 1: the view sits on a level (lambda
// - level is 0), one fetch per fragment. 2: the view's level blends with its parent; a
// coarser tile showing where finer ones are missing gets weight 0.
uniform float u_lambda;
void main() {
#if ORTHO_LOD == 1
  o_colour = displayColour(own());
#else
  float weight = v_info.z >= 0 ? clamp(u_lambda - float(v_info.x), 0.0, 1.0) : 0.0;
  o_colour = displayColour(mix(own(), parent(), weight));
#endif
}
#endif
)";

struct Instance {
  float rect[4];
  float origins[4];
  int32_t info[4];
  int32_t tile[2];
};

class TileQuadsRenderer final : public RendererBase {
 public:
  TileQuadsRenderer(const ImageInfo& info, const RendererOptions& options)
      : RendererBase(info, options) {}

  Result<void> init() {
    chooseBlockFormat();
    // One program per way of filtering across tile edges, chosen here: a software renderer
    // runs both sides of a branch on every fragment, and the borderless fetches cost a
    // bordered archive's frames several times the bilinear sample it needs.
    // Likewise one program per way of choosing the level of detail: orthographic views have
    // one for the whole view, so their fragments need no derivatives, no discard and, on a
    // level, no second fetch. The orthographic ones are linked first: the base class keeps
    // u_view_projection of the last program linked, the perspective one.
    for (int mode : {1, 2, 0}) {
      const std::string fragment =
          fmt::format(
              "#define BORDERLESS {}\n#define ORTHO_LOD {}\n#define BLOCKS {}\n"
              "#define TEXEL_LAYER {}\n",
              info_.border_px == 0 ? 1 : 0, mode, blockMode() ? 1 : 0, kTexelLayer) +
          kFragmentShader;
      TESSERA_TRY(linkRendererProgram("tile-quads", kVertexShader, fragment.c_str()));
      const GLuint p = program_.get();
      glProgramUniform1i(p, glGetUniformLocation(p, "u_tiles"), 0);
      glProgramUniform1f(p, glGetUniformLocation(p, "u_tile_size"), float(info_.tile_size_px));
      glProgramUniform1f(p, glGetUniformLocation(p, "u_border"), float(info_.border_px));
      glProgramUniform1f(p, glGetUniformLocation(p, "u_stored_side"),
                         float(info_.storedTileSidePx()));
      if (blockMode()) {
        glProgramUniform1i(p, glGetUniformLocation(p, "u_blocks"), 1);
        glProgramUniform1f(p, glGetUniformLocation(p, "u_block_side"), float(blockSidePx()));
      }
      if (mode == 0) break;
      OrthoProgram& ortho = ortho_programs_[mode - 1];
      ortho.view_projection = glGetUniformLocation(p, "u_view_projection");
      ortho.lambda = glGetUniformLocation(p, "u_lambda");
      ortho.program = std::move(program_);
    }
    glGetIntegerv(GL_MAX_ARRAY_TEXTURE_LAYERS, &max_layers_);
    TESSERA_TRY(growLayers(primary(), std::max<uint32_t>(1, options_.initial_layers)));
    // With blocks, decoded tiles are the few uniform ones: a small array, grown on demand.
    if (blockMode()) TESSERA_TRY(growLayers(texels_, kInitialTexelLayersBesideBlocks));

    instances_buffer_ = createBuffer();
    vertex_array_ = createVertexArray();
    const GLuint vao = vertex_array_.get();
    glVertexArrayVertexBuffer(vao, 0, instances_buffer_.get(), 0, sizeof(Instance));
    glVertexArrayBindingDivisor(vao, 0, 1);
    glEnableVertexArrayAttrib(vao, 0);
    glVertexArrayAttribFormat(vao, 0, 4, GL_FLOAT, GL_FALSE, offsetof(Instance, rect));
    glVertexArrayAttribBinding(vao, 0, 0);
    glEnableVertexArrayAttrib(vao, 1);
    glVertexArrayAttribFormat(vao, 1, 4, GL_FLOAT, GL_FALSE, offsetof(Instance, origins));
    glVertexArrayAttribBinding(vao, 1, 0);
    glEnableVertexArrayAttrib(vao, 2);
    glVertexArrayAttribIFormat(vao, 2, 4, GL_INT, offsetof(Instance, info));
    glVertexArrayAttribBinding(vao, 2, 0);
    glEnableVertexArrayAttrib(vao, 3);
    glVertexArrayAttribIFormat(vao, 3, 2, GL_INT, offsetof(Instance, tile));
    glVertexArrayAttribBinding(vao, 3, 0);
    neighbours_buffer_ = createBuffer();
    return {};
  }

  const ApplyResult& apply(const FrameUpdate& update) override {
    const auto started = Clock::now();
    beginApply();
    for (const TileId& id : update.releases) release(id);
    // Layers first, so a tile with no room is declined before any byte is copied.
    // Storage for every tile the streamer may keep resident, allocated once at the first
    // frame (nothing to copy yet): growing by doubling later copies every layer in use, a
    // 50-150 ms stall of the render thread on llvmpipe each time.
    if (!sized_from_bound_) {
      sized_from_bound_ = true;
      const uint64_t wanted =
          std::min<uint64_t>(update.resident_tiles_bound, uint64_t(std::max(max_layers_, 1)));
      if (wanted > primary().capacity && layers_.empty())
        (void)growLayers(primary(), uint32_t(wanted));
    }
    pending_.clear();
    size_t room = stagingRoom();
    for (const auto& tile : update.uploads) {
      // Not this image's, or no room left in the staging ring this frame (offered again).
      const size_t bytes = tile->uploadBytes().size();
      if (!holds(*tile) || bytes > room) {
        decline(tile->id);
        continue;
      }
      // A tile held in the other array (now blocks, before decoded) moves.
      auto existing = layers_.find(tile->id);
      if (existing != layers_.end() && inBlocks(existing->second) != tile->keptAsBlocks())
        release(tile->id);
      existing = layers_.find(tile->id);
      const GLint layer =
          existing != layers_.end() ? existing->second : takeLayer(tile->keptAsBlocks());
      if (layer < 0) {
        decline(tile->id);
        continue;
      }
      layers_[tile->id] = layer;
      pending_.push_back({tile.get(), uint32_t(layer)});
      room -= bytes;
    }
    uploadStaged(pending_, [&](const DecodedTile& tile, uint32_t layer, size_t offset) {
      const auto* source = reinterpret_cast<const void*>(offset);
      if (tile.keptAsBlocks()) {
        const GLsizei side = GLsizei(blockSidePx());
        glCompressedTextureSubImage3D(blocks_.texture.get(), 0, 0, 0, GLint(layer), side, side, 1,
                                      block_format_, GLsizei(tile.blocks.bytes.size()), source);
        return;
      }
      const GLsizei side = GLsizei(info_.storedTileSidePx());
      glTextureSubImage3D(texels_.texture.get(), 0, 0, 0, GLint(layer) - texelTag(), side, side, 1,
                          texel_format_.pixel_format, texel_format_.pixel_type, source);
    });
    return endApply(started, layers_.size());
  }

  void draw(const View& view) override {
    const auto started = Clock::now();
    const ViewProjection transform = beginDraw(view);
    collectInstances(view, transform);
    stats_.tiles_drawn = uint32_t(instances_.size());
    if (!instances_.empty()) {
      glNamedBufferData(instances_buffer_.get(), GLsizeiptr(instances_.size() * sizeof(Instance)),
                        instances_.data(), GL_STREAM_DRAW);
      if (info_.border_px == 0) bindNeighbours(view.image);
      glUseProgram(programFor(view, transform));
      glBindTextureUnit(0, texels_.texture.get());
      if (blockMode()) glBindTextureUnit(1, blocks_.texture.get());
      glBindVertexArray(vertex_array_.get());
      glDrawArraysInstanced(GL_TRIANGLE_STRIP, 0, 4, GLsizei(instances_.size()));
      glBindVertexArray(0);
    }
    stats_.draw_cpu_ms = msSince(started);
  }

  bool resident(const TileId& tile) const override { return layers_.count(tile) > 0; }
  bool takesStoredBlocks() const override { return blockMode(); }
  RendererKind kind() const override { return RendererKind::kTileQuads; }

 private:
  /// A program for orthographic views and its own uniforms.
  struct OrthoProgram {
    Program program;
    GLint view_projection = -1;
    GLint lambda = -1;
  };

  /// The program that draws `view`, its uniforms set: for an orthographic view the one on a
  /// level (lambda - level is 0) or the one that blends with the parent, else the per-fragment
  /// one.
  GLuint programFor(const View& view, const ViewProjection& transform) {
    if (view.kind != View::Kind::kOrtho) return program_.get();
    const double texels_per_pixel = texelsPerPixelOf(view.ortho);
    const uint32_t level = desiredLevelFor(texels_per_pixel, info_.level_count);
    const double lambda = std::log2(texels_per_pixel);
    const bool blends = level + 1 < info_.level_count && lambda > double(level);
    const OrthoProgram& ortho = ortho_programs_[blends ? 1 : 0];
    const GLuint p = ortho.program.get();
    glProgramUniformMatrix4fv(p, ortho.view_projection, 1, GL_FALSE, transform.matrix);
    glProgramUniform1f(p, ortho.lambda, GLfloat(lambda));
    return p;
  }

  /// The quads of this frame: every resident tile that meets the view's footprint (the
  /// runtime's, for field-of-view culling), coarse levels first so that finer tiles draw
  /// over them where they apply.
  void collectInstances(const View& view, const ViewProjection& transform) {
    const tessera::detail::Footprint footprint = tessera::detail::footprintOf(view, info_);
    instances_.clear();
    // An orthographic view has one level of detail everywhere: tiles finer than it would
    // discard every fragment, and a coarser tile whose children are all resident is hidden
    // under them. Skipping both keeps overdraw near one layer instead of one per resident
    // level (docs/rendering.md has the cost on llvmpipe). Perspective views keep every
    // level: their level of detail varies across a tile.
    const bool ortho = view.kind == View::Kind::kOrtho;
    const uint32_t finest_drawn =
        ortho ? desiredLevelFor(texelsPerPixelOf(view.ortho), info_.level_count) : 0;
    for (const auto& [id, layer] : layers_) {
      if (id.level < finest_drawn) continue;
      const double span = std::ldexp(double(info_.tile_size_px), int(id.level));
      const double x0 = id.x * span, y0 = id.y * span;
      const double x1 = std::min(x0 + span, double(info_.width_px));
      const double y1 = std::min(y0 + span, double(info_.height_px));
      if (!meetsFootprint(footprint, x0, y0, x1, y1)) continue;  // outside the field of view
      if (ortho && hiddenByChildren(id, finest_drawn, footprint)) continue;
      Instance instance{};
      instance.rect[0] = float(x0 - transform.anchor_x);
      instance.rect[1] = float(y0 - transform.anchor_y);
      instance.rect[2] = float(x1 - transform.anchor_x);
      instance.rect[3] = float(y1 - transform.anchor_y);
      instance.origins[0] = instance.rect[0];
      instance.origins[1] = instance.rect[1];
      const bool coarsest = id.level + 1 >= info_.level_count;
      int32_t parent_layer = -1;
      if (!coarsest) {
        TileId parent{id.image, id.level + 1, id.x / 2, id.y / 2};
        auto it = layers_.find(parent);
        if (it != layers_.end()) {
          parent_layer = it->second;
          instance.origins[2] = float(parent.x * 2 * span - transform.anchor_x);
          instance.origins[3] = float(parent.y * 2 * span - transform.anchor_y);
        }
      }
      instance.tile[0] = int32_t(id.x);
      instance.tile[1] = int32_t(id.y);
      instance.info[0] = int32_t(id.level);
      instance.info[1] = layer;
      instance.info[2] = parent_layer;
      instance.info[3] = coarsest ? 1 : 0;
      instances_.push_back(instance);
    }
    std::sort(instances_.begin(), instances_.end(),
              [](const Instance& a, const Instance& b) { return a.info[0] > b.info[0]; });
  }

  static bool meetsFootprint(const tessera::detail::Footprint& footprint, double x0, double y0,
                             double x1, double y1) {
    return x1 > footprint.x0 && x0 < footprint.x1 && y1 > footprint.y0 && y0 < footprint.y1;
  }

  /// True when every child of `id` that lies on the image and meets the view's footprint is
  /// resident, at a level an orthographic view at `finest_drawn` draws: they hide all of it
  /// that is on screen. Children off screen do not count: with them, each coarse level of the
  /// stack drew a whole-screen quad whose every fragment was discarded, eight layers of
  /// overdraw at full detail (a frame cost about 8 times the floor on llvmpipe).
  bool hiddenByChildren(const TileId& id, uint32_t finest_drawn,
                        const tessera::detail::Footprint& footprint) const {
    if (id.level == 0 || id.level - 1 < finest_drawn) return false;
    const uint32_t child_level = id.level - 1;
    const double span = std::ldexp(double(info_.tile_size_px), int(child_level));
    for (uint32_t dy = 0; dy < 2; ++dy)
      for (uint32_t dx = 0; dx < 2; ++dx) {
        const uint32_t cx = id.x * 2 + dx, cy = id.y * 2 + dy;
        if (cx >= info_.tilesX(child_level) || cy >= info_.tilesY(child_level)) continue;
        if (!meetsFootprint(footprint, cx * span, cy * span, (cx + 1) * span, (cy + 1) * span))
          continue;
        if (!layers_.count({id.image, child_level, cx, cy})) return false;
      }
    return true;
  }

  /// Borderless tiles filter across their edges with texels of their resident neighbours:
  /// per instance, the layers of the 3 x 3 tiles around it and around its parent (-1 where
  /// none is resident), in the storage buffer the fragment shader reads.
  void bindNeighbours(uint32_t image) {
    neighbours_.clear();
    auto layerOf = [&](uint32_t level, int64_t x, int64_t y) {
      if (x < 0 || y < 0) return GLint(-1);
      auto it = layers_.find({image, level, uint32_t(x), uint32_t(y)});
      return it == layers_.end() ? GLint(-1) : it->second;
    };
    for (const Instance& instance : instances_) {
      const uint32_t level = uint32_t(instance.info[0]);
      for (int generation = 0; generation < 2; ++generation) {
        const int64_t x = instance.tile[0] >> generation, y = instance.tile[1] >> generation;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx)
            neighbours_.push_back(level + generation < info_.level_count
                                      ? layerOf(level + generation, x + dx, y + dy)
                                      : GLint(-1));
      }
    }
    glNamedBufferData(neighbours_buffer_.get(), GLsizeiptr(neighbours_.size() * sizeof(GLint)),
                      neighbours_.data(), GL_STREAM_DRAW);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, neighbours_buffer_.get());
  }

  /// One texture array of tiles and its free layers (as layers_ names them: tagged).
  struct LayerArray {
    Texture texture;
    uint32_t capacity = 0;
    std::vector<GLint> free;
  };

  /// Block mode: this image's tiles are bc1/bc7 (its default codec), RGB or RGBA, and the
  /// context samples the format. Grey bc tiles stay decoded: their swizzle reads alpha from
  /// the second channel, which a block texture does not have. A JPEG image whose tiles the
  /// streamer transcodes (RendererOptions::transcode_to_bc1) is drawn as a bc1 one, grey
  /// included: its blocks hold the grey in R, G and B alike, and the one-channel swizzle
  /// reads R.
  void chooseBlockFormat() {
    const bool transcoded = info_.default_codec == Codec::kJpeg && options_.transcode_to_bc1;
    const Codec codec = transcoded ? Codec::kBc1 : info_.default_codec;
    const bool rgb_or_rgba = info_.channels == 3 || (info_.channels == 4 && codec == Codec::kBc7) ||
                             (info_.channels == 1 && transcoded);
    if ((codec != Codec::kBc1 && codec != Codec::kBc7) || !rgb_or_rgba ||
        info_.sample_type != SampleType::kU8)
      return;
    block_format_ = blockInternalFormat(codec);
    if (block_format_ != 0) block_codec_ = codec;
  }
  bool blockMode() const { return block_codec_ != Codec::kRaw; }
  /// What layers_ adds to a layer of texels_ in block mode, to tell the arrays apart.
  GLint texelTag() const { return blockMode() ? kTexelLayer : 0; }
  bool inBlocks(GLint layer) const { return blockMode() && layer < kTexelLayer; }
  /// The array the streamer's residency bound sizes: blocks in block mode.
  LayerArray& primary() { return blockMode() ? blocks_ : texels_; }
  uint64_t layerBytes(bool blocks) const {
    if (!blocks) return info_.storedTileBytes();
    const uint64_t blocks_along = blockSidePx() / 4;
    return blocks_along * blocks_along * (block_codec_ == Codec::kBc1 ? 8 : 16);
  }

  /// (Re)allocates `array` with `layers` layers, copying the layers in use.
  Result<void> growLayers(LayerArray& array, uint32_t layers) {
    const bool blocks = &array == &blocks_;
    const GLsizei side = GLsizei(blocks ? blockSidePx() : info_.storedTileSidePx());
    Texture grown = blocks
                        ? createBlockTileArray(block_format_, info_.channels, side, GLsizei(layers))
                        : createTileArray(info_.channels, info_.sample_type, side, GLsizei(layers));
    if (!grown)
      return fail(
          ErrorCode::kTooLarge,
          fmt::format("tile array of {} layers of {} px does not fit in GPU memory", layers, side));
    if (array.texture && array.capacity > 0)
      glCopyImageSubData(array.texture.get(), GL_TEXTURE_2D_ARRAY, 0, 0, 0, 0, grown.get(),
                         GL_TEXTURE_2D_ARRAY, 0, 0, 0, 0, side, side, GLsizei(array.capacity));
    const GLint tag = blocks ? 0 : texelTag();
    for (uint32_t layer = array.capacity; layer < layers; ++layer)
      array.free.push_back(GLint(layers - 1 - (layer - array.capacity)) + tag);
    array.texture = std::move(grown);
    array.capacity = layers;
    ++stats_.storage_allocations;
    stats_.gpu_bytes = uint64_t(blocks_.capacity) * layerBytes(true) +
                       uint64_t(texels_.capacity) * layerBytes(false);
    return {};
  }

  /// A free layer of the block or the texel array, growing it when none is left; -1 at the
  /// driver's limit.
  GLint takeLayer(bool blocks) {
    LayerArray& array = blocks ? blocks_ : texels_;
    if (array.free.empty()) {
      const uint32_t limit = uint32_t(std::max(max_layers_, 1));
      if (array.capacity >= limit) return -1;
      if (!growLayers(array, std::min(limit, array.capacity * 2))) return -1;
    }
    GLint layer = array.free.back();
    array.free.pop_back();
    return layer;
  }

  void release(const TileId& id) {
    auto it = layers_.find(id);
    if (it == layers_.end()) return;
    (inBlocks(it->second) ? blocks_ : texels_).free.push_back(it->second);
    layers_.erase(it);
  }

  /// Layer names from here on are layers of texels_ (block mode); far above any driver's
  /// GL_MAX_ARRAY_TEXTURE_LAYERS.
  static constexpr GLint kTexelLayer = 1 << 20;
  static constexpr uint32_t kInitialTexelLayersBesideBlocks = 8;

  OrthoProgram ortho_programs_[2];  ///< on a level; blending with the parent
  LayerArray texels_;               ///< decoded tiles
  LayerArray blocks_;               ///< tiles kept as blocks of block_codec_ (block mode)
  GLenum block_format_ = 0;         ///< blocks_'s internal format; 0 outside block mode
  bool sized_from_bound_ = false;   ///< the first apply sized the array from the streamer
  GLint max_layers_ = 0;
  /// Each resident tile's layer: of blocks_ below kTexelLayer, else of texels_ (minus it).
  std::unordered_map<TileId, GLint, TileIdHash> layers_;
  std::vector<PendingUpload> pending_;  ///< scratch of apply
  Buffer instances_buffer_;
  std::vector<Instance> instances_;
  Buffer neighbours_buffer_;
  std::vector<GLint> neighbours_;
};

}  // namespace

Result<std::unique_ptr<Renderer>> createTileQuadsRenderer(const ImageInfo& info,
                                                          const RendererOptions& options) {
  auto renderer = std::make_unique<TileQuadsRenderer>(info, options);
  TESSERA_TRY(renderer->init());
  return std::unique_ptr<Renderer>(std::move(renderer));
}

}  // namespace tessera::gl
