#include "scene_textures.h"

#include <algorithm>

#include <fmt/format.h>

namespace tessera::gl {

namespace {

/// GL level sizes halve with the floor (max(1, w >> L)) where the archive's halve with the
/// ceiling: a GL level is at most one texel smaller, and the tiles' last column or row past it
/// is not uploaded.
GLsizei glLevelSide(uint32_t side_px, uint32_t level) {
  return GLsizei(std::max<uint32_t>(1, side_px >> std::min<uint32_t>(level, 31)));
}

}  // namespace

SceneTextureMirror::SceneTextureMirror(std::shared_ptr<const SceneArchive> archive,
                                       std::vector<SceneTexture> records,
                                       const SceneRenderOptions& options)
    : archive_(std::move(archive)),
      records_(std::move(records)),
      options_(options),
      gpu_(records_.size()) {}

void SceneTextureMirror::beginFrame() {
  staged_.clear();
  touched_.clear();
  budget_left_bytes_ = options_.upload_budget_bytes;
  staged_finer_ = false;
}

GLuint SceneTextureMirror::handle(uint32_t texture) const {
  return texture < gpu_.size() ? gpu_[texture].texture.get() : 0;
}

uint32_t SceneTextureMirror::sampledLevel(uint32_t texture) const {
  if (texture >= gpu_.size()) return 0;
  return gpu_[texture].texture ? gpu_[texture].sampled : records_[texture].info.level_count;
}

uint64_t SceneTextureMirror::levelTexelBytes(uint32_t texture, uint32_t level) const {
  const ImageInfo& info = records_[texture].info;
  return uint64_t(glLevelSide(info.width_px, level)) * glLevelSide(info.height_px, level) * 4;
}

SceneTextureMirror::GpuTexture& SceneTextureMirror::allocate(uint32_t texture) {
  GpuTexture& gpu = gpu_[texture];
  const ImageInfo& info = records_[texture].info;
  const uint32_t levels = std::max(1u, info.level_count);
  gpu.texture = createTexture(GL_TEXTURE_2D);
  glTextureStorage2D(gpu.texture.get(), GLsizei(levels), tileInternalFormat(info.channels),
                     glLevelSide(info.width_px, 0), glLevelSide(info.height_px, 0));
  setChannelSwizzle(gpu.texture, info.channels);
  glTextureParameteri(gpu.texture.get(), GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
  glTextureParameteri(gpu.texture.get(), GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTextureParameteri(gpu.texture.get(), GL_TEXTURE_WRAP_S, GL_REPEAT);
  glTextureParameteri(gpu.texture.get(), GL_TEXTURE_WRAP_T, GL_REPEAT);
  glTextureParameteri(gpu.texture.get(), GL_TEXTURE_MAX_LEVEL, GLint(levels - 1));
  if (options_.unloaded_level_rgba) {
    const uint32_t rgba = *options_.unloaded_level_rgba;
    const uint8_t colour[4] = {uint8_t(rgba), uint8_t(rgba >> 8), uint8_t(rgba >> 16),
                               uint8_t(rgba >> 24)};
    for (uint32_t level = 0; level < levels; ++level)
      glClearTexImage(gpu.texture.get(), GLint(level), GL_RGBA, GL_UNSIGNED_BYTE, colour);
  }
  gpu.uploaded = gpu.sampled = gpu.staged = levels;
  return gpu;
}

void SceneTextureMirror::setSampledLevel(uint32_t texture, uint32_t level) {
  GpuTexture& gpu = gpu_[texture];
  const uint32_t levels = std::max(1u, records_[texture].info.level_count);
  level = std::min(level, levels - 1);
  if (level == gpu.sampled) return;
  // Both clamps: the base level keeps the sampler off the levels below it (they may hold
  // nothing), the minimum LOD keeps the level selection from reaching below it either.
  glTextureParameteri(gpu.texture.get(), GL_TEXTURE_BASE_LEVEL, GLint(level));
  glTextureParameterf(gpu.texture.get(), GL_TEXTURE_MIN_LOD, float(level));
  for (uint32_t l = std::min(level, gpu.sampled); l < std::max(level, gpu.sampled); ++l) {
    const uint64_t bytes = levelTexelBytes(texture, l);
    if (level < gpu.sampled)
      sampled_bytes_ += bytes;
    else
      sampled_bytes_ -= bytes;
  }
  gpu.sampled = level;
}

bool SceneTextureMirror::require(uint32_t texture, const SceneStreamer& streamer) {
  if (texture >= gpu_.size()) return false;
  if (gpu_[texture].texture) return true;
  if (options_.all_levels_resident) return loadWhole(texture);
  const Image* coarsest = streamer.coarsestTile(texture);
  if (!coarsest) return false;
  GpuTexture& gpu = allocate(texture);
  const uint32_t level = gpu.uploaded - 1;
  staged_.push_back({texture, level, {coarsest}});
  gpu.staged = level;
  return true;
}

void SceneTextureMirror::refine(uint32_t texture, const SceneStreamer& streamer) {
  if (options_.all_levels_resident || texture >= gpu_.size() || !gpu_[texture].texture) return;
  GpuTexture& gpu = gpu_[texture];
  const uint32_t resident = streamer.residentLevel(texture);
  // An eviction: sample no finer than the streamer holds (the GPU copy stays until the level
  // comes back, when it needs no second upload).
  if (resident > gpu.sampled && gpu.staged == gpu.sampled) {
    setSampledLevel(texture, resident);
    gpu.staged = resident;
  }
  const uint32_t staged_before = gpu.staged;
  while (gpu.staged > resident && gpu.staged > 0) {
    const uint32_t level = gpu.staged - 1;
    if (level >= gpu.uploaded) {  // still on the GPU from before an eviction
      gpu.staged = level;
      continue;
    }
    const std::vector<Image>* tiles = streamer.levelTiles(texture, level);
    if (!tiles) break;
    const uint64_t bytes = levelTexelBytes(texture, level);
    if (staged_finer_ && bytes > budget_left_bytes_) break;
    budget_left_bytes_ -= std::min(bytes, budget_left_bytes_);
    staged_finer_ = true;
    StagedLevel staged{texture, level, {}};
    for (const Image& tile : *tiles) staged.tiles.push_back(&tile);
    staged_.push_back(std::move(staged));
    gpu.staged = level;
  }
  if (gpu.staged < staged_before) touched_.push_back(texture);
}

void SceneTextureMirror::writeLevel(uint32_t texture, uint32_t level,
                                    const std::vector<const Image*>& tiles,
                                    const std::vector<const uint8_t*>& data) {
  const ImageInfo& info = records_[texture].info;
  const GLsizei width = glLevelSide(info.width_px, level);
  const GLsizei height = glLevelSide(info.height_px, level);
  const GLsizei tile = GLsizei(info.tile_size_px);
  const uint32_t tiles_x = info.tilesX(level);
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  glPixelStorei(GL_UNPACK_ROW_LENGTH, GLint(info.storedTileSidePx()));
  glPixelStorei(GL_UNPACK_SKIP_PIXELS, GLint(info.border_px));
  glPixelStorei(GL_UNPACK_SKIP_ROWS, GLint(info.border_px));
  for (size_t i = 0; i < tiles.size(); ++i) {
    const Image& stored = *tiles[i];
    const GLsizei x = GLsizei(i % tiles_x) * tile, y = GLsizei(i / tiles_x) * tile;
    const GLsizei w = std::min(tile, width - x), h = std::min(tile, height - y);
    // A decoded tile has the stored side and the image's channels (SceneArchive::decodeTile);
    // anything else would be read out of range, so it is skipped.
    if (w <= 0 || h <= 0 || stored.channels != info.channels ||
        stored.width_px != info.storedTileSidePx() || stored.height_px != info.storedTileSidePx())
      continue;
    glTextureSubImage2D(gpu_[texture].texture.get(), GLint(level), x, y, w, h,
                        tilePixelFormat(info.channels), GL_UNSIGNED_BYTE, data[i]);
  }
  glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
  glPixelStorei(GL_UNPACK_SKIP_PIXELS, 0);
  glPixelStorei(GL_UNPACK_SKIP_ROWS, 0);
}

void SceneTextureMirror::flush(SceneDrawStats& stats) {
  if (!staged_.empty()) {
    std::vector<std::pair<const uint8_t*, size_t>> sources;
    for (const StagedLevel& level : staged_)
      for (const Image* tile : level.tiles)
        sources.emplace_back(tile->texels.data(), tile->texels.size());
    staging_.stage(sources);
    size_t offset = 0;  // staged one after the other, in this order
    for (const StagedLevel& level : staged_) {
      std::vector<const uint8_t*> data;
      for (const Image* tile : level.tiles) {
        data.push_back(reinterpret_cast<const uint8_t*>(offset));
        offset += tile->texels.size();
      }
      writeLevel(level.texture, level.level, level.tiles, data);
      GpuTexture& gpu = gpu_[level.texture];
      gpu.uploaded = std::min(gpu.uploaded, level.level);
      stats.bytes_uploaded += levelTexelBytes(level.texture, level.level);
      if (level.level + 1 < records_[level.texture].info.level_count) ++stats.levels_uploaded;
    }
    staging_.unbind();
  }
  for (const StagedLevel& level : staged_) touched_.push_back(level.texture);
  // Levels still on the GPU from before an eviction come back without an upload.
  for (uint32_t texture : touched_) {
    const GpuTexture& gpu = gpu_[texture];
    if (gpu.staged < gpu.sampled) setSampledLevel(texture, gpu.staged);
  }
  staged_.clear();
  touched_.clear();
}

Result<std::vector<std::vector<Image>>> SceneTextureMirror::readWhole(uint32_t texture) {
  const SceneTexture& record = records_[texture];
  auto cached = nodes_.find(record.node);
  if (cached == nodes_.end()) {
    Result<SceneNode> node = archive_->node(record.node);
    if (!node) return forwardError(node);
    Result<NodeContents> contents = archive_->readNode(*node);
    if (!contents) return forwardError(contents);
    cached = nodes_.emplace(record.node, std::move(*contents)).first;
  }
  const auto& stored = cached->second.textures;
  auto it = std::find_if(stored.begin(), stored.end(),
                         [&](const NodeTexture& t) { return t.texture == texture; });
  const uint32_t levels = record.info.level_count;
  if (it == stored.end() || it->levels.size() < levels)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: texture {} is not stored at node {}",
                                                 archive_->name(), texture, record.node));
  std::vector<std::vector<Image>> out(levels);
  CodecScratch scratch;
  for (uint32_t level = 0; level + 1 < levels; ++level) {
    const std::vector<TileEntry>& entries = it->levels[level];
    const uint32_t tiles_x = record.info.tilesX(level);
    for (size_t i = 0; i < entries.size(); ++i) {
      std::vector<uint8_t> payload;
      if (entries[i].hasPayload()) {
        payload.resize(entries[i].length_bytes);
        Result<void> read = archive_->source().read(entries[i].offset_bytes, payload);
        if (!read) return forwardError(read);
      }
      Result<Image> tile =
          archive_->decodeTile(texture, record.info, level, uint32_t(i % tiles_x),
                               uint32_t(i / tiles_x), entries[i], payload, &scratch);
      if (!tile) return forwardError(tile);
      out[level].push_back(std::move(*tile));
    }
  }
  Result<Image> coarsest = archive_->readCoarsest(record, &scratch);
  if (!coarsest) return forwardError(coarsest);
  out[levels - 1].push_back(std::move(*coarsest));
  return out;
}

bool SceneTextureMirror::loadWhole(uint32_t texture) {
  Result<std::vector<std::vector<Image>>> levels = readWhole(texture);
  if (!levels || levels->empty()) {
    if (read_failures_++ == 0)
      first_read_error_ =
          levels ? fmt::format("texture {} has no levels", texture) : levels.error().message;
    return false;
  }
  allocate(texture);
  for (uint32_t level = 0; level < levels->size(); ++level) {
    std::vector<const Image*> tiles;
    std::vector<const uint8_t*> data;
    for (const Image& tile : (*levels)[level]) {
      tiles.push_back(&tile);
      data.push_back(tile.texels.data());
    }
    writeLevel(texture, level, tiles, data);
  }
  GpuTexture& gpu = gpu_[texture];
  gpu.uploaded = gpu.staged = 0;
  setSampledLevel(texture, 0);
  return true;
}

}  // namespace tessera::gl
