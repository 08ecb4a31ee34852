#include "scene_loader.h"

#include <algorithm>
#include <set>

#include <fmt/format.h>

#include "scene_lod.h"

namespace tessera::detail {
namespace {

// The bytes of `range` inside the job's buffer, which starts at `base`; empty (and false)
// when the range is not wholly inside.
bool sliceOf(std::span<const uint8_t> buffer, uint64_t base, uint64_t offset, uint64_t length,
             std::span<const uint8_t>* out) {
  if (offset < base || offset - base > buffer.size() || length > buffer.size() - (offset - base)) {
    return false;
  }
  *out = buffer.subspan(offset - base, length);
  return true;
}

Result<std::vector<Image>> decodeLevel(const SceneArchive& archive, uint32_t texture,
                                       const ImageInfo& info, uint32_t level,
                                       std::span<const TileEntry> tiles,
                                       std::span<const uint8_t> buffer, uint64_t base,
                                       CodecScratch* scratch) {
  const uint32_t tiles_x = info.tilesX(level);
  std::vector<Image> out;
  out.reserve(tiles.size());
  for (size_t i = 0; i < tiles.size(); ++i) {
    std::span<const uint8_t> payload;
    if (tiles[i].kind == TileKind::kEncoded &&
        !sliceOf(buffer, base, tiles[i].offset_bytes, tiles[i].length_bytes, &payload)) {
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: texture {} level {} tile {} lies outside the read",
                              archive.name(), texture, level, i));
    }
    TESSERA_ASSIGN_OR_RETURN(Image tile,
                             archive.decodeTile(texture, info, level, uint32_t(i % tiles_x),
                                                uint32_t(i / tiles_x), tiles[i], payload, scratch));
    out.push_back(std::move(tile));
  }
  return out;
}

// Whether every encoded tile of a level lies in the read [base, base + size).
bool levelInside(const std::vector<TileEntry>& tiles, uint64_t base, uint64_t size) {
  for (const TileEntry& tile : tiles) {
    if (tile.kind == TileKind::kEncoded &&
        (tile.offset_bytes < base || tile.offset_bytes - base > size ||
         tile.length_bytes > size - (tile.offset_bytes - base))) {
      return false;
    }
  }
  return true;
}

// The finest level any object of `parsed` in view needs of each texture (coarsest when none).
std::vector<uint32_t> wantedLevels(const LoaderContext& context, const ReadJob& job,
                                   const std::vector<ParsedNode>& parsed) {
  std::vector<uint32_t> wanted;
  const Frustum frustum = frustumOf(job.camera);
  for (const ParsedNode& node : parsed) {
    for (const SceneObject& object : node.contents.objects) {
      if (!boxMayBeVisible(frustum, object.bounds)) continue;
      for (uint32_t t : object.textures) {
        if (t == kNoTexture || t >= context.textures.size()) continue;
        const ImageInfo& info = context.textures[t].info;
        if (wanted.size() <= t) wanted.resize(context.textures.size(), UINT32_MAX);
        wanted[t] =
            std::min(wanted[t], objectLod(job.camera, object.bounds, info, job.lod_bias).level);
      }
    }
  }
  return wanted;
}

// Parses the job's nodes, decodes their meshes, the coarsest level of every texture their
// objects use, and the levels the job's camera wants of the textures stored in them.
Result<void> parseNodes(const LoaderContext& context, const ReadJob& job,
                        std::span<const uint8_t> buffer, CodecScratch* scratch, ReadResult& out) {
  const SceneArchive& archive = *context.archive;
  const uint64_t base = job.read.range.offset_bytes;
  std::set<uint32_t> used;
  for (const SceneNode& node : job.parse) {
    // The node's block, or the prefix of it the read holds (a large node's head and pages).
    std::span<const uint8_t> block;
    const uint64_t end = base + buffer.size();
    if (node.own.offset_bytes < base || node.own.offset_bytes >= end ||
        !sliceOf(buffer, base, node.own.offset_bytes,
                 std::min(node.own.length_bytes, end - node.own.offset_bytes), &block)) {
      return fail(ErrorCode::kCorrupt, fmt::format("{}: node {} lies outside read of node {}",
                                                   archive.name(), node.index, job.read.node));
    }
    TESSERA_ASSIGN_OR_RETURN(NodeContents contents, archive.parseNode(node, block));
    for (const SceneMesh& mesh : contents.meshes) {
      // Blobs past a prefix are read later, as object reads of the meshes in view.
      std::span<const uint8_t> blob;
      if (!sliceOf(buffer, base, mesh.blob.offset_bytes, mesh.blob.length_bytes, &blob)) continue;
      TESSERA_ASSIGN_OR_RETURN(MeshData data, archive.decodeMesh(mesh, blob));
      out.meshes.push_back({mesh.index, std::move(data)});
    }
    for (const SceneObject& object : contents.objects) {
      for (uint32_t t : object.textures) {
        if (t != kNoTexture) used.insert(t);
      }
    }
    out.nodes.push_back({node.index, std::move(contents)});
  }
  for (uint32_t t : used) {
    if (t >= context.textures.size()) {
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: texture {} out of range", archive.name(), t));
    }
    const SceneTexture& texture = context.textures[t];
    const std::span<const uint8_t> coarse(context.coarse_block);
    TESSERA_ASSIGN_OR_RETURN(
        std::vector<Image> tile,
        decodeLevel(archive, t, texture.info, texture.info.level_count - 1,
                    std::span(&texture.coarsest, 1), coarse, context.coarse_offset_bytes, scratch));
    out.coarsest.push_back({t, std::move(tile[0])});
  }
  const std::vector<uint32_t> wanted = wantedLevels(context, job, out.nodes);
  for (const ParsedNode& node : out.nodes) {
    for (const NodeTexture& texture : node.contents.textures) {
      if (texture.texture >= wanted.size() || wanted[texture.texture] == UINT32_MAX) continue;
      // Coarse to fine, so the streamer's chain of resident levels grows one level at a time.
      for (uint32_t level = texture.info.level_count - 1; level-- > wanted[texture.texture];) {
        if (level < texture.levels.size() &&
            !levelInside(texture.levels[level], base, buffer.size())) {
          break;  // past a prefix: the streamer refines the chain from here
        }
        if (level >= texture.levels.size()) {
          return fail(
              ErrorCode::kCorrupt,
              fmt::format("{}: texture {} has {} levels of tile entries, not {}", archive.name(),
                          texture.texture, texture.levels.size(), texture.info.level_count));
        }
        TESSERA_ASSIGN_OR_RETURN(std::vector<Image> tiles,
                                 decodeLevel(archive, texture.texture, texture.info, level,
                                             texture.levels[level], buffer, base, scratch));
        out.levels.push_back({texture.texture, level, std::move(tiles)});
      }
    }
  }
  return {};
}

}  // namespace

ReadResult runReadJob(const LoaderContext& context, ReadJob job, CodecScratch* scratch) {
  ReadResult out;
  out.job = std::move(job);
  const ReadJob& j = out.job;
  std::vector<uint8_t> buffer(j.read.range.length_bytes);
  Result<void> read = context.archive->source().read(j.read.range.offset_bytes, buffer);
  if (!read.has_value()) {
    out.error = read.error().message;
    return out;
  }
  out.bytes_read = buffer.size();
  Result<void> parsed = parseNodes(context, j, buffer, scratch, out);
  for (size_t i = 0; parsed.has_value() && i < j.meshes.size(); ++i) {
    std::span<const uint8_t> blob;
    const SceneMesh& mesh = j.meshes[i];
    if (!sliceOf(buffer, j.read.range.offset_bytes, mesh.blob.offset_bytes, mesh.blob.length_bytes,
                 &blob)) {
      parsed = fail(ErrorCode::kCorrupt, fmt::format("{}: mesh {} lies outside the read",
                                                     context.archive->name(), mesh.index));
      break;
    }
    Result<MeshData> data = context.archive->decodeMesh(mesh, blob);
    if (!data.has_value()) {
      parsed = fail(data.error().code, data.error().message);
      break;
    }
    out.meshes.push_back({mesh.index, std::move(*data)});
  }
  for (size_t i = 0; parsed.has_value() && i < j.levels.size(); ++i) {
    const LevelJob& level = j.levels[i];
    Result<std::vector<Image>> tiles =
        decodeLevel(*context.archive, level.texture, level.info, level.level, level.tiles, buffer,
                    j.read.range.offset_bytes, scratch);
    if (!tiles.has_value()) {
      parsed = fail(tiles.error().code, tiles.error().message);
      break;
    }
    out.levels.push_back({level.texture, level.level, std::move(*tiles)});
  }
  if (!parsed.has_value()) {
    out.error = parsed.error().message;
    out.nodes.clear();
    out.meshes.clear();
    out.coarsest.clear();
    out.levels.clear();
  }
  return out;
}

SceneLoaderPool::SceneLoaderPool(std::shared_ptr<const LoaderContext> context, uint32_t threads)
    : context_(std::move(context)) {
  for (uint32_t i = 0; i < std::max(1u, threads); ++i) threads_.emplace_back([this] { work(); });
}

SceneLoaderPool::~SceneLoaderPool() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
    queue_.clear();
  }
  wake_.notify_all();
  for (std::thread& thread : threads_) thread.join();
}

void SceneLoaderPool::submit(ReadJob job) {
  {
    std::lock_guard lock(mutex_);
    queue_.push_back(std::move(job));
  }
  wake_.notify_one();
}

std::vector<ReadResult> SceneLoaderPool::drain() {
  std::vector<ReadResult> out;
  std::lock_guard lock(results_mutex_);
  out.swap(results_);
  return out;
}

uint32_t SceneLoaderPool::pending() const {
  std::lock_guard lock(mutex_);
  return uint32_t(queue_.size()) + running_;
}

void SceneLoaderPool::waitIdle() {
  std::unique_lock lock(mutex_);
  idle_.wait(lock, [this] { return queue_.empty() && running_ == 0; });
}

void SceneLoaderPool::work() {
  // Per-thread decoder state, passed explicitly to every decode of this worker.
  CodecScratch scratch;
  for (;;) {
    ReadJob job;
    {
      std::unique_lock lock(mutex_);
      wake_.wait(lock, [this] { return stop_ || !queue_.empty(); });
      if (stop_) return;
      job = std::move(queue_.front());
      queue_.pop_front();
      ++running_;
    }
    ReadResult result = runReadJob(*context_, std::move(job), &scratch);
    {
      std::lock_guard lock(results_mutex_);
      results_.push_back(std::move(result));
    }
    {
      std::lock_guard lock(mutex_);
      --running_;
    }
    idle_.notify_all();
  }
}

}  // namespace tessera::detail
