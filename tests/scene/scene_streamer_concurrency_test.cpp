// The streamer's render thread against its workers: frames never wait for reads, and the
// invariants hold on every frame while reads finish at any moment (run under TSan).
#include <tessera/scene_stream.h>

#include <cmath>

#include <gtest/gtest.h>

#include <tessera/scene_build.h>

#include "scene/scene_test_support.h"

namespace tessera {
namespace {

TEST(SceneStreamerConcurrency, FramesRunWhileWorkersLoadAndEvict) {
  test::ScratchDir dir;
  const SceneBuildOptions build = test::testCityOptions(dir, "500:50:11");
  ASSERT_TRUE(buildScene(build).has_value());
  auto archive = SceneArchive::openFile(build.output);
  ASSERT_TRUE(archive.has_value());
  SceneStreamOptions options;
  options.worker_threads = 3;
  options.moving_texel_budget_bytes = 64 << 10;
  options.still_texel_budget_bytes = 128 << 10;
  options.still_after_frames = 5;
  options.link = LinkCost{0.001, 1e8};
  auto streamer = SceneStreamer::open(*archive, options);
  ASSERT_TRUE(streamer.has_value());
  const SceneSummary& summary = (*archive)->summary();
  PerspectiveView camera;
  camera.pitch_rad = 0;
  camera.viewport_w = 640;
  camera.viewport_h = 480;
  uint64_t applied = 0, drawn = 0, visible = 0;
  // At least 3000 frames, and on until 50 reads have come back while frames ran: the loop
  // never waits for them, so how many frames that takes depends on the machine.
  for (int frame = 0; frame < 3000 || (applied < 50 && frame < 5000000); ++frame) {
    // Circles low over the city, pausing every 200 frames so still budgets apply too.
    const double t = (frame / 200) % 2 ? std::floor(frame / 200.0) : frame / 200.0;
    camera.eye_x = (summary.bounds.min[0] + summary.bounds.max[0]) / 2 + 60 * std::cos(t);
    camera.eye_z = (summary.bounds.min[2] + summary.bounds.max[2]) / 2 + 60 * std::sin(t);
    camera.eye_y = summary.bounds.max[1] + 40 + 30 * std::sin(3 * t);
    const SceneFrameStats stats = (*streamer)->update(camera);
    ASSERT_LE(stats.texel_bytes, stats.texel_budget_bytes) << "frame " << frame;
    ASSERT_EQ(stats.untextured_objects, 0u) << "frame " << frame;
    applied += stats.results_applied;
    visible += stats.visible_leaves;
    for (uint32_t o : (*streamer)->drawableObjects()) {
      const SceneObject* object = (*streamer)->object(o);
      ASSERT_NE(object, nullptr);
      ASSERT_NE((*streamer)->mesh(object->mesh), nullptr);
      if (object->textures[0] != kNoTexture) {
        ASSERT_NE((*streamer)->coarsestTile(object->textures[0]), nullptr);
      }
      ++drawn;
    }
  }
  (*streamer)->waitForReads();
  EXPECT_GT(visible, 0u);
  EXPECT_GE(applied, 50u) << "results arrived while frames ran";
  EXPECT_GT(drawn, 0u);
  EXPECT_EQ((*streamer)->totals().read_errors, 0u);
}

}  // namespace
}  // namespace tessera
