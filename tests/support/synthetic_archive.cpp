#include "support/synthetic_archive.h"

#include <filesystem>
#include <map>
#include <mutex>
#include <tuple>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <tessera/build.h>

#include "support/test_images.h"

namespace tessera::test {

const std::vector<uint8_t>& syntheticArchiveBytes(const SyntheticArchiveSpec& spec) {
  using Key = std::tuple<uint32_t, uint32_t, uint32_t, uint32_t, uint32_t, int, uint32_t>;
  static std::mutex mutex;  // guards built
  static std::map<Key, std::vector<uint8_t>> built;
  std::lock_guard lock(mutex);
  Key key{spec.width_px,     spec.height_px,  spec.seed,     spec.channels,
          spec.tile_size_px, int(spec.codec), spec.border_px};
  auto it = built.find(key);
  if (it != built.end()) return it->second;

  const std::filesystem::path dir =
      std::filesystem::path(::testing::TempDir()) / fmt::format("tessera_synthetic_{}", ::getpid());
  std::filesystem::create_directories(dir);
  BuildOptions options;
  options.inputs = {fmt::format("synthetic:{}x{}:{}:{}", spec.width_px, spec.height_px, spec.seed,
                                spec.channels)};
  // The synthetic source makes RGB and RGBA only; grey images come from a test PNG.
  if (spec.channels <= 2) {
    PngSpec png;
    png.width_px = spec.width_px;
    png.height_px = spec.height_px;
    png.colour = spec.channels == 1 ? PngColour::kGray : PngColour::kGrayAlpha;
    const std::string path = (dir / fmt::format("grey{}_{}x{}_{}.png", spec.channels, spec.width_px,
                                                spec.height_px, spec.seed))
                                 .string();
    const std::string error = writePng(
        path, png, makeTestPixels(spec.width_px, spec.height_px, spec.channels, spec.seed));
    if (!error.empty()) ADD_FAILURE() << path << ": " << error;
    options.inputs = {path};
  }
  options.output =
      (dir / fmt::format("s{}x{}_{}_{}_{}_{}_b{}.tess", spec.width_px, spec.height_px, spec.seed,
                         spec.channels, spec.tile_size_px, codecName(spec.codec), spec.border_px))
          .string();
  options.tile_size_px = spec.tile_size_px;
  options.border_px = spec.border_px;
  options.codec = spec.codec;
  options.threads = 2;
  std::vector<uint8_t> bytes;
  if (auto report = buildArchive(options); !report) {
    ADD_FAILURE() << "building " << options.inputs[0] << ": " << report.error().message;
  } else {
    bytes = readFileBytes(options.output);
    std::filesystem::remove(options.output);
  }
  return built.emplace(key, std::move(bytes)).first->second;
}

std::shared_ptr<Archive> openArchiveOrFail(std::shared_ptr<ByteSource> source) {
  auto archive = Archive::open(std::move(source));
  if (!archive) {
    ADD_FAILURE() << archive.error().message;
    return nullptr;
  }
  return *archive;
}

void warmDirectory(const Archive& archive) {
  for (const TileId& id : allTiles(archive)) {
    auto entry = archive.tileEntry(id);
    ASSERT_TRUE(entry) << entry.error().message;
  }
}

std::vector<TileId> allTiles(const Archive& archive) {
  std::vector<TileId> tiles;
  const ImageInfo& info = archive.images()[0];
  for (uint32_t level = info.level_count; level-- > 0;)
    for (uint32_t y = 0; y < info.tilesY(level); ++y)
      for (uint32_t x = 0; x < info.tilesX(level); ++x) tiles.push_back({0, level, x, y});
  return tiles;
}

}  // namespace tessera::test
