// Coverage hints at run time (docs/scenes.md, "Coverage hints"): the camera cell's hints in
// screen pixels, the level for a pixel count by hand, and the streamer ranking reads and
// sizing levels by hints where the projected-size estimate says otherwise.
#include "scene_hints.h"

#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include <tessera/scene_build.h>
#include <tessera/scene_stream.h>

#include "scene/scene_test_support.h"

namespace tessera {
namespace {

using test::ScratchDir;

CoverageHints oneCellHints(const Box3& bounds, uint32_t textures,
                           std::vector<CoverageHint> entries) {
  CoverageHints h;
  h.up_axis = 1;
  h.origin_u = bounds.min[0];
  h.origin_v = bounds.min[2];
  h.cell_size = std::max(bounds.max[0] - bounds.min[0], bounds.max[2] - bounds.min[2]) + 1;
  h.eye_low = bounds.min[1];
  h.eye_high = bounds.max[1];
  h.resolution_px = 64;
  h.texture_count = textures;
  std::sort(entries.begin(), entries.end(),
            [](const CoverageHint& a, const CoverageHint& b) { return a.texture < b.texture; });
  h.entries = std::move(entries);
  h.cell_first = {0, uint32_t(h.entries.size())};
  return h;
}

TEST(SceneHints, CellPixelsAreTheShareOfTheSphereAtTheCameraDensity) {
  const Box3 bounds{{0, 0, 0}, {10, 5, 10}};
  auto hints = std::make_shared<const CoverageHints>(
      oneCellHints(bounds, 3, {{0, 65535}, {2, 6554}}));  // all, and about a tenth
  detail::CellHints cell(hints, {1, 2, 2}, 3);
  PerspectiveView camera;
  camera.eye_x = 5;
  camera.eye_y = 1;
  camera.eye_z = 5;
  ASSERT_TRUE(cell.setCamera(camera));
  const double sphere = 4 * M_PI / std::pow(pixelAngle(camera), 2);
  EXPECT_NEAR(cell.pixels(0), sphere, 1e-6 * sphere);
  EXPECT_NEAR(cell.pixels(2), sphere * 6554 / 65535, 1e-6 * sphere);
  EXPECT_EQ(cell.pixels(1), 0);
  EXPECT_NEAR(cell.nodePixels(1), cell.pixels(0), 1e-9);
  EXPECT_NEAR(cell.nodePixels(2), cell.pixels(2), 1e-9);
  EXPECT_GT(cell.floorPixels(), 0);
  EXPECT_LT(cell.floorPixels(), cell.pixels(2));
  camera.eye_x = 1000;  // far outside the one cell
  EXPECT_FALSE(cell.setCamera(camera));
  EXPECT_EQ(cell.nodePixels(1), 0) << "leaving the grid drops the cell's hints";
}

TEST(SceneHints, LevelForPixelsByHand) {
  ImageInfo info;
  info.width_px = info.height_px = 256;
  info.tile_size_px = 64;
  info.level_count = 3;
  EXPECT_EQ(detail::levelForPixels(info, 65536, 0), 0u);   // one texel a pixel
  EXPECT_EQ(detail::levelForPixels(info, 200000, 0), 0u);  // more pixels than texels
  EXPECT_EQ(detail::levelForPixels(info, 16384, 0), 1u);   // sqrt(4) = 2 texels a pixel
  EXPECT_EQ(detail::levelForPixels(info, 4096, 0), 2u);
  EXPECT_EQ(detail::levelForPixels(info, 10, 0), 2u) << "clamped to the coarsest";
  EXPECT_EQ(detail::levelForPixels(info, 0, 0), 2u);
  EXPECT_EQ(detail::levelForPixels(info, 65536, 1), 1u) << "the bias makes it coarser";
}

TEST(SceneHints, StreamerReadsTheHintedLeafFirstAndSizesTexturesBeforeTheirUsersArrive) {
  ScratchDir dir;
  // More leaves than the streamer reads in its first wave (kWantsPerSlot per slot), so the
  // order it picks them in shows.
  const SceneBuildOptions build = test::testCityOptions(dir, "600:200:3");
  ASSERT_TRUE(buildScene(build).has_value());
  auto archive = SceneArchive::openFile(build.output);
  ASSERT_TRUE(archive.has_value());
  const SceneArchive& scene = **archive;
  auto nodes = scene.allNodes();
  auto textures = scene.textures(0, scene.summary().textures);
  ASSERT_TRUE(nodes && textures);
  const PerspectiveView camera = test::cameraAbove(scene.summary(), 400, 1.2);

  // The last leaf in tree order holding a texture of its own: the projected-size order (tree
  // order, one leaf a frame here) reads it last; the hints say its texture fills the view.
  uint32_t target_leaf = 0, target_texture = 0;
  for (const SceneTexture& t : *textures)
    if ((*nodes)[t.node].isLeaf() && t.node >= target_leaf) {
      target_leaf = t.node;
      target_texture = t.index;
    }
  ASSERT_GT(target_leaf, 0u);
  std::vector<CoverageHint> entries = {{target_texture, 50000}};
  std::vector<uint32_t> root_textures;
  for (const SceneTexture& t : *textures)
    if (t.node == 0) {
      entries.push_back({t.index, 2000});
      root_textures.push_back(t.index);
    }
  ASSERT_FALSE(root_textures.empty()) << "the generator promotes its popular textures";
  auto hints = std::make_shared<const CoverageHints>(
      oneCellHints(scene.summary().bounds, scene.summary().textures, entries));

  SceneStreamOptions options;
  options.max_reads_in_flight = 1;  // one wave of leaves a frame: the order shows
  options.worker_threads = 1;
  options.link = LinkCost{0, 500e6};
  auto leafKnown = [&](const SceneStreamer& s, uint32_t leaf) {
    return s.object((*nodes)[leaf].first_object) != nullptr;
  };
  for (bool use : {false, true}) {
    options.use_coverage_hints = use;
    options.coverage_hints = hints;
    auto streamer = SceneStreamer::open(*archive, options);
    ASSERT_TRUE(streamer.has_value()) << streamer.error().message;
    const SceneFrameStats first = (*streamer)->update(camera);
    EXPECT_EQ(first.hinted, use);
    (*streamer)->waitForReads();
    const SceneFrameStats second = (*streamer)->update(camera);
    EXPECT_EQ(leafKnown(**streamer, target_leaf), use)
        << (use ? "hints: the leaf whose texture fills the view comes first"
                : "projected size: tree order, the target leaf last");
    if (!use) {
      EXPECT_EQ(second.hint_only_textures, 0u);
      continue;
    }
    // The root arrived with the target leaf; its textures whose users have not arrived are
    // asked for at the level their hint pixels need, before any feedback.
    EXPECT_GT(second.hint_only_textures, 0u);
    bool refined = false;
    for (uint32_t t : root_textures)
      refined |= (*streamer)->wantedLevel(t) < (*textures)[t].info.level_count - 1;
    EXPECT_TRUE(refined) << "a hinted root texture wants a level finer than its coarsest";
  }
}

TEST(SceneHints, StreamerRefusesHintsForAnotherScene) {
  ScratchDir dir;
  const SceneBuildOptions build = test::testCityOptions(dir, "50:10:1");
  ASSERT_TRUE(buildScene(build).has_value());
  auto archive = SceneArchive::openFile(build.output);
  ASSERT_TRUE(archive.has_value());
  SceneStreamOptions options;
  options.coverage_hints =
      std::make_shared<const CoverageHints>(oneCellHints((*archive)->summary().bounds, 11, {}));
  auto streamer = SceneStreamer::open(*archive, options);
  ASSERT_FALSE(streamer.has_value());
  EXPECT_NE(streamer.error().message.find("coverage hints for 11 textures"), std::string::npos);
}

}  // namespace
}  // namespace tessera
