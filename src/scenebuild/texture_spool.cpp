#include "texture_spool.h"

#include <unistd.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>

#include <fmt/format.h>

#include "builder/texture_pyramid.h"
#include "importers.h"

namespace tessera::detail {

namespace {

// A temporary folder for embedded images, removed with everything in it.
class TempDir {
 public:
  TempDir() {
    std::string pattern =
        (std::filesystem::temp_directory_path() / "tessera-scene-XXXXXX").string();
    if (::mkdtemp(pattern.data()) != nullptr) path_ = pattern;
  }
  ~TempDir() {
    std::error_code ec;
    if (!path_.empty()) std::filesystem::remove_all(path_, ec);
  }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

struct SpoolState {
  const ImportedScene& scene;
  const std::vector<uint32_t>& order;
  const TextureSpoolOptions& options;
  const TempFile& spool;
  TempDir temp;
  std::atomic<uint64_t> next{0}, done{0}, spool_end{0};
  std::atomic<bool> stop{false};
  std::mutex error_mutex;  // guards error
  std::optional<Error> error;
  std::mutex source_mutex;  // guards sources
  std::map<int32_t, std::shared_ptr<const Image>> sources;
  std::vector<SpooledTexture> out;

  void recordError(Error e) {
    std::lock_guard lock(error_mutex);
    if (!error) error = std::move(e);
    stop = true;
  }
};

// A generator source, decoded once and shared by every crop of it.
Result<std::shared_ptr<const Image>> cropSource(SpoolState& state, int32_t index) {
  std::lock_guard lock(state.source_mutex);
  if (auto it = state.sources.find(index); it != state.sources.end()) return it->second;
  if (index < 0 || size_t(index) >= state.scene.crop_sources.size())
    return fail(ErrorCode::kInternal, "crop source out of range");
  TESSERA_ASSIGN_OR_RETURN(
      Image image, readImageFile(state.scene.crop_sources[index], state.options.max_side_px));
  // Scene textures are drawn as 8-bit texels; wider files (16-bit PNGs) are narrowed.
  auto shared = std::make_shared<const Image>(toEightBit(std::move(image)));
  state.sources.emplace(index, shared);
  return shared;
}

Result<Image> crop(const Image& source, const TextureSource& t) {
  const uint32_t w = std::min(t.crop_width, source.width_px);
  const uint32_t h = std::min(t.crop_height, source.height_px);
  const uint32_t x = uint32_t(uint64_t(source.width_px - w) * t.crop_x >> 16);
  const uint32_t y = uint32_t(uint64_t(source.height_px - h) * t.crop_y >> 16);
  Image out(w, h, source.channels);
  for (uint32_t r = 0; r < h; ++r)
    std::memcpy(out.row(r), source.row(y + r) + size_t(x) * source.channels, out.strideBytes());
  return out;
}

Result<Image> loadTexture(SpoolState& state, uint32_t index) {
  const TextureSource& t = state.scene.textures[index];
  if (t.crop_source >= 0) {
    TESSERA_ASSIGN_OR_RETURN(std::shared_ptr<const Image> source, cropSource(state, t.crop_source));
    return crop(*source, t);
  }
  TESSERA_ASSIGN_OR_RETURN(std::string file,
                           textureFile(t, state.scene.source, state.temp.path(), index));
  Result<Image> image = readImageFile(file, state.options.max_side_px);
  if (!t.bytes.empty()) std::remove(file.c_str());
  if (!image) return image;
  return toEightBit(std::move(*image));
}

Result<SpooledTexture> encodeOne(SpoolState& state, uint32_t index, CodecScratch& scratch) {
  const TextureSource& t = state.scene.textures[index];
  const std::string what = fmt::format("{}: {}", state.scene.source, t.name);
  Result<Image> loaded = loadTexture(state, index);
  if (!loaded) return fail(loaded.error().code, what + ": " + loaded.error().message);
  const Image& image = *loaded;
  ImageInfo info;
  info.width_px = image.width_px;
  info.height_px = image.height_px;
  info.channels = image.channels;
  info.tile_size_px = state.options.tile_size_px;
  const uint32_t tiles =
      (std::max(image.width_px, image.height_px) + info.tile_size_px - 1) / info.tile_size_px;
  info.page_tiles_log2 = std::max(3u, uint32_t(std::bit_width(tiles - 1)));
  if (info.page_tiles_log2 > 8)
    return fail(ErrorCode::kTooLarge,
                fmt::format("{}: {}x{} px is over 256 tiles per side; use larger tiles", what,
                            image.width_px, image.height_px));
  EncodeOptions encode;
  encode.quality = state.options.quality;
  encode.effort = state.options.effort;
  TESSERA_ASSIGN_OR_RETURN(EncodedPyramid pyramid,
                           encodePyramid(image, info, state.options.codec, encode, &scratch, what));
  SpooledTexture out;
  out.info = pyramid.info;
  out.info.name = t.path.empty() ? t.name : std::filesystem::path(t.path).filename().string();
  std::vector<uint8_t> chunk;
  for (const auto& level : pyramid.payloads)
    for (const auto& payload : level) chunk.insert(chunk.end(), payload.begin(), payload.end());
  const uint64_t base = state.spool_end.fetch_add(chunk.size());
  if (!chunk.empty()) TESSERA_TRY(state.spool.pwrite(base, chunk));
  uint64_t pos = base;
  for (uint32_t level = 0; level < pyramid.entries.size(); ++level) {
    for (size_t k = 0; k < pyramid.entries[level].size(); ++k) {
      TileEntry& entry = pyramid.entries[level][k];
      if (entry.kind != TileKind::kEncoded) continue;
      entry.offset_bytes = pos;
      pos += entry.length_bytes;
      out.payload_bytes += entry.length_bytes;
      ++out.tiles_encoded;
    }
  }
  out.entries = std::move(pyramid.entries);
  return out;
}

void worker(SpoolState& state, const std::atomic<bool>* cancel) {
  CodecScratch scratch;
  while (!state.stop) {
    if (cancel && cancel->load()) {
      state.recordError({ErrorCode::kCancelled, state.scene.source + ": build cancelled"});
      return;
    }
    const uint64_t k = state.next.fetch_add(1);
    if (k >= state.order.size()) return;
    Result<SpooledTexture> texture = encodeOne(state, state.order[k], scratch);
    if (!texture) {
      state.recordError(texture.error());
      return;
    }
    state.out[k] = std::move(*texture);
    ++state.done;
  }
}

}  // namespace

Result<std::string> textureFile(const TextureSource& texture, const std::string& scene_name,
                                const std::string& temp_dir, uint32_t index) {
  if (!texture.path.empty()) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(texture.path, ec))
      return fail(ErrorCode::kNotFound, fmt::format("texture file {} not found", texture.path));
    return texture.path;
  }
  const std::vector<uint8_t>& b = texture.bytes;
  const bool png = b.size() >= 8 && std::memcmp(b.data(), "\x89PNG\r\n\x1a\n", 8) == 0;
  const bool jpeg = b.size() >= 3 && b[0] == 0xFF && b[1] == 0xD8 && b[2] == 0xFF;
  if (!png && !jpeg)
    return fail(ErrorCode::kUnsupported,
                fmt::format("embedded image of type '{}' is not PNG or JPEG",
                            texture.mime_type.empty() ? "unknown" : texture.mime_type));
  if (temp_dir.empty())
    return fail(ErrorCode::kIo, scene_name + ": no temporary folder for embedded images");
  const std::string path = fmt::format("{}/texture-{}.{}", temp_dir, index, png ? "png" : "jpg");
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return fail(ErrorCode::kIo, path + ": cannot create");
  const bool written = std::fwrite(b.data(), 1, b.size(), f) == b.size();
  if (std::fclose(f) != 0 || !written) return fail(ErrorCode::kIo, path + ": write failed");
  return path;
}

Result<std::vector<SpooledTexture>> spoolTextures(const ImportedScene& scene,
                                                  const std::vector<uint32_t>& order,
                                                  const TextureSpoolOptions& options,
                                                  const TempFile& spool, uint64_t* spool_bytes,
                                                  const std::function<void(uint64_t)>& on_done,
                                                  const std::atomic<bool>* cancel) {
  SpoolState state{scene, order, options, spool};
  state.out.resize(order.size());
  const uint32_t threads =
      std::max(1u, std::min<uint32_t>(options.threads, uint32_t(order.size())));
  std::vector<std::thread> pool;
  for (uint32_t i = 0; i < threads; ++i) pool.emplace_back([&] { worker(state, cancel); });
  while (state.done < order.size() && !state.stop) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    if (on_done) on_done(state.done);
  }
  for (std::thread& t : pool) t.join();
  if (state.error) return Unexpected(*state.error);
  if (on_done) on_done(state.done);
  *spool_bytes = state.spool_end;
  return std::move(state.out);
}

}  // namespace tessera::detail
