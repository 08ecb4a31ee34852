// The GPU compositor (fragment shader, headless llvmpipe in CI) against the CPU compositor:
// random instance sets at every level, each blend mode alone, clips, masks over a height
// layer; every texel within 1 per channel (issue 29), with the histogram of differences
// printed and recorded.
#include <algorithm>
#include <array>
#include <atomic>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <thread>

#include <gtest/gtest.h>

#include <tessera/archive.h>
#include <tessera/brushes.h>
#include <tessera/procedural_build.h>
#include <tessera/gl.h>
#include <tessera/procedural.h>

#include "../procedural/procedural_fixtures.h"
#include "gl_test_context.h"
#include "support/test_images.h"

namespace tessera {
namespace {

/// Differences per channel between the GPU and CPU tiles: histogram[d] counts channel values
/// that differ by d (the last bin by 3 or more).
struct Difference {
  std::array<uint64_t, 4> histogram{};
  uint32_t max = 0;
  void add(const Image& gpu, const Image& cpu) {
    ASSERT_EQ(gpu.width_px, cpu.width_px);
    ASSERT_EQ(gpu.height_px, cpu.height_px);
    ASSERT_EQ(gpu.channels, cpu.channels);
    ASSERT_EQ(gpu.texels.size(), cpu.texels.size());
    for (size_t i = 0; i < gpu.texels.size(); ++i) {
      const uint32_t d = uint32_t(std::abs(int(gpu.texels[i]) - int(cpu.texels[i])));
      max = std::max(max, d);
      ++histogram[std::min<uint32_t>(d, 3)];
    }
  }
  std::string text() const {
    return "|gpu - cpu| = 0: " + std::to_string(histogram[0]) +
           ", 1: " + std::to_string(histogram[1]) + ", 2: " + std::to_string(histogram[2]) +
           ", >=3: " + std::to_string(histogram[3]);
  }
};

/// The fixtures' brushes (every blend mode, masked ones over a height layer) for a w x h
/// texture, and a GPU compositor of them on the shared context; null (test failed) on error.
std::unique_ptr<GpuCompositor> testCompositor(uint32_t w, uint32_t h) {
  test::sharedGlContext();
  auto set = BrushSet::prepare(testing::testBrushes(), {testing::heightLayer(w / 4, h / 4)}, w, h);
  EXPECT_TRUE(set) << set.error().message;
  if (!set) return nullptr;
  auto gpu = GpuCompositor::create(*set);
  EXPECT_TRUE(gpu) << gpu.error().message;
  return gpu ? std::move(*gpu) : nullptr;
}

/// Composites every tile of every level of a w x h texture (64-px tiles, `border`) on both
/// sides and adds the differences.
void compareEveryTile(GpuCompositor& gpu, const std::vector<BrushInstance>& instances, uint32_t w,
                      uint32_t h, uint32_t border, Difference& difference, size_t* tiles) {
  const BrushSet& set = gpu.brushSet();
  for (uint32_t level = 0; level < levelCountFor(w, h, 64); ++level) {
    const uint32_t tiles_x = (std::max(1u, (w + (1u << level) - 1) >> level) + 63) / 64;
    const uint32_t tiles_y = (std::max(1u, (h + (1u << level) - 1) >> level) + 63) / 64;
    for (uint32_t ty = 0; ty < tiles_y; ++ty) {
      for (uint32_t tx = 0; tx < tiles_x; ++tx) {
        const TileGeometry tile{level, tx, ty, 64, border, w, h};
        Image on_gpu, on_cpu;
        ASSERT_TRUE(compositeTile(set, tile, instances, on_cpu));
        Result<void> composited = gpu.compositeTile(tile, instances, on_gpu);
        ASSERT_TRUE(composited) << composited.error().message;
        difference.add(on_gpu, on_cpu);
        ++*tiles;
      }
    }
  }
}

TEST(GpuCompositor, EveryLevelWithinOneOfTheCpu) {
  const uint32_t w = 300, h = 200;
  std::unique_ptr<GpuCompositor> gpu = testCompositor(w, h);
  ASSERT_TRUE(gpu);
  const BrushSet* set = &gpu->brushSet();
  Difference difference;
  size_t tiles = 0;
  {
    const uint32_t seed = 42;
    std::vector<BrushInstance> instances =
        testing::randomInstances(200, w, h, uint32_t(set->brushes().size()), seed);
    std::sort(instances.begin(), instances.end(), drawsBefore);
    for (uint32_t border : {0u, 3u})
      compareEveryTile(*gpu, instances, w, h, border, difference, &tiles);
  }
  std::printf("GPU compositor, %zu tiles: %s\n", tiles, difference.text().c_str());
  ::testing::Test::RecordProperty("histogram", difference.text());
  EXPECT_GT(tiles, 20u);
  EXPECT_LE(difference.max, 1u) << difference.text();
  // Something was drawn: the comparison is not between two empty tiles.
  EXPECT_GT(difference.histogram[0], 0u);
}

TEST(GpuCompositor, EachBlendModeAloneWithinOneOfTheCpu) {
  const uint32_t w = 160, h = 130;
  std::unique_ptr<GpuCompositor> gpu = testCompositor(w, h);
  ASSERT_TRUE(gpu);
  const BrushSet* set = &gpu->brushSet();
  std::vector<BrushInstance> all =
      testing::randomInstances(200, w, h, uint32_t(set->brushes().size()), 5);
  // Each brush (normal, multiply, add, overlay, slope- and height-masked) over the opaque base.
  for (uint32_t brush = 1; brush < set->brushes().size(); ++brush) {
    std::vector<BrushInstance> instances;
    for (const BrushInstance& instance : all) {
      if (instance.brush != 0 && instance.brush != brush) continue;
      instances.push_back(instance);
      instances.back().layer = instance.brush == 0 ? 0 : 1;
    }
    std::sort(instances.begin(), instances.end(), drawsBefore);
    Difference difference;
    size_t tiles = 0;
    compareEveryTile(*gpu, instances, w, h, 1, difference, &tiles);
    std::printf("brush %s (%s): %s\n", set->brushes()[brush].name.c_str(),
                blendModeName(set->brushes()[brush].blend), difference.text().c_str());
    EXPECT_LE(difference.max, 1u) << set->brushes()[brush].name << ": " << difference.text();
  }
}

TEST(GpuCompositor, ClipsAsTheCpuDoes) {
  const uint32_t w = 128, h = 128;
  std::unique_ptr<GpuCompositor> gpu = testCompositor(w, h);
  ASSERT_TRUE(gpu);
  const BrushSet* set = &gpu->brushSet();
  std::vector<BrushInstance> instances =
      testing::randomInstances(120, w, h, uint32_t(set->brushes().size()), 9);
  std::sort(instances.begin(), instances.end(), drawsBefore);
  std::mt19937 rng(3);
  std::vector<TileClip> clips;
  for (size_t n = 0; n < instances.size(); ++n) {
    const uint16_t x0 = uint16_t(rng() % 40), y0 = uint16_t(rng() % 40);
    clips.push_back({x0, y0, uint16_t(x0 + rng() % 40), uint16_t(y0 + rng() % 40)});
  }
  const TileGeometry tile{0, 0, 0, 64, 2, w, h};
  Image on_gpu, on_cpu;
  ASSERT_TRUE(compositeTile(*set, tile, instances, on_cpu, clips));
  ASSERT_TRUE(gpu->compositeTile(tile, instances, on_gpu, clips));
  Difference difference;
  difference.add(on_gpu, on_cpu);
  EXPECT_LE(difference.max, 1u) << difference.text();
  // The clips mattered: without them the tile differs.
  Image unclipped;
  ASSERT_TRUE(gpu->compositeTile(tile, instances, unclipped));
  EXPECT_NE(unclipped.texels, on_gpu.texels);
}

TEST(GpuCompositor, MissingBrushIsAnErrorNotAPicture) {
  std::unique_ptr<GpuCompositor> gpu = testCompositor(64, 64);
  ASSERT_TRUE(gpu);
  const BrushSet* set = &gpu->brushSet();
  BrushInstance instance;
  instance.id = 1;
  instance.brush = uint32_t(set->brushes().size());
  instance.x_px = 32;
  instance.y_px = 32;
  instance.radius_px = 10;
  Image out;
  Result<void> composited =
      gpu->compositeTile({0, 0, 0, 64, 0, 64, 64}, std::span(&instance, 1), out);
  ASSERT_FALSE(composited);
  EXPECT_EQ(composited.error().code, ErrorCode::kCorrupt);
}

// A mixed archive read through the GPU tile compositor (Archive::setTileCompositor): every
// procedural tile, read from two threads at once, within 1 of the CPU's.
TEST(GpuTileCompositor, ArchiveCompositesProceduralTilesOnTheGpu) {
  const std::string dir = test::testTempDir();
  const uint32_t w = 300, h = 200;
  {
    auto db = openSqliteBrushDatabase(dir + "world.sqlite", true);
    ASSERT_TRUE(db) << db.error().message;
    ASSERT_TRUE((*db)->setTextureExtent({w, h}));
    std::vector<Brush> brushes = testing::testBrushes();
    brushes.resize(5);  // no masks: no base layer
    for (const Brush& brush : brushes) ASSERT_TRUE((*db)->addBrush(brush));
    ASSERT_TRUE((*db)->addInstances(testing::randomInstances(150, w, h, 5, 11)));
  }
  ProceduralBuildOptions options;
  options.database = dir + "world.sqlite";
  options.output = dir + "mixed.tess";
  options.tile_size_px = 64;
  options.border_px = 1;
  options.codec = Codec::kZstd;
  options.threads = 2;
  ASSERT_TRUE(buildProceduralArchive(options));
  auto archive = Archive::openFile(options.output);
  ASSERT_TRUE(archive) << archive.error().message;
  auto compositor = createGpuTileCompositor();
  ASSERT_TRUE(compositor) << compositor.error().message;
  std::vector<TileId> procedural;
  const ImageInfo& info = (*archive)->images()[0];
  for (uint32_t level = 0; level < info.level_count; ++level)
    for (uint32_t y = 0; y < info.tilesY(level); ++y)
      for (uint32_t x = 0; x < info.tilesX(level); ++x)
        if ((*(*archive)->tileEntry({0, level, x, y})).kind == TileKind::kProcedural)
          procedural.push_back({0, level, x, y});
  ASSERT_FALSE(procedural.empty());
  std::vector<Image> on_cpu;
  for (const TileId& id : procedural) on_cpu.push_back(*(*archive)->readTile(id));
  // Counts the tiles handed to the GPU: the archive must composite through it.
  struct Counting final : TileCompositor {
    std::shared_ptr<TileCompositor> gpu;
    std::atomic<size_t> calls{0};
    Result<void> composite(const std::shared_ptr<const BrushSet>& brushes, const TileGeometry& tile,
                           std::span<const BrushInstance> instances,
                           std::span<const TileClip> clips, Image& out) override {
      ++calls;
      return gpu->composite(brushes, tile, instances, clips, out);
    }
  };
  auto counting = std::make_shared<Counting>();
  counting->gpu = *compositor;
  (*archive)->setTileCompositor(counting);
  std::vector<Image> on_gpu(procedural.size());
  auto read = [&](size_t first) {
    for (size_t i = first; i < procedural.size(); i += 2) {
      auto tile = (*archive)->readTile(procedural[i]);
      if (tile) on_gpu[i] = std::move(*tile);
    }
  };
  std::thread other(read, 1);
  read(0);
  other.join();
  Difference difference;
  for (size_t i = 0; i < procedural.size(); ++i) difference.add(on_gpu[i], on_cpu[i]);
  EXPECT_EQ(counting->calls.load(), procedural.size());
  EXPECT_LE(difference.max, 1u) << difference.text();
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace tessera
