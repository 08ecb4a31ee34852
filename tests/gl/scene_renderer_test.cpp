// The scene renderer on llvmpipe with a small viewport and a small synthetic city: the streamed
// picture at rest against the same renderer with every texture whole, no object drawn without
// its texture, mip sampling clamped to the levels that arrived, and the upload budget.
#include <tessera/scene_render.h>

#include <gtest/gtest.h>

#include <tessera/gl.h>

#include "scene/scene_test_support.h"

namespace tessera {
namespace {

using test::ScratchDir;

GlContext& context() {
  static std::unique_ptr<GlContext> context = [] {
    auto created = GlContext::createHeadless();
    return created ? std::move(*created) : nullptr;
  }();
  if (!context) throw std::runtime_error("no headless OpenGL context");
  context->makeCurrent();
  return *context;
}

std::shared_ptr<SceneArchive> buildCity(const ScratchDir& dir) {
  auto archive = SceneArchive::openFile(test::buildSyntheticCity(dir, "80:16:5"));
  EXPECT_TRUE(archive.has_value()) << archive.error().message;
  return archive ? *archive : nullptr;
}

// The city is y-up: pitch 0 looks straight down -y and pi/2 along +z with y up the screen.
// From just outside the city's -z edge, a little above the ground and looking slightly down,
// the first facades fill the view: close enough for the sampler to want level 0.
PerspectiveView streetLevel(const SceneSummary& summary) {
  PerspectiveView camera;
  camera.eye_x = (summary.bounds.min[0] + summary.bounds.max[0]) / 2;
  camera.eye_y = summary.bounds.min[1] + 6;
  camera.eye_z = summary.bounds.min[2] - 4;
  camera.pitch_rad = 1.45;
  camera.fov_y_rad = 1.0;
  camera.viewport_w = 160;
  camera.viewport_h = 120;
  return camera;
}

struct Settled {
  SceneFrameStats frame;
  SceneDrawStats draw;
  int frames = 0;
};

// Frames at one camera until nothing is read, picked up or uploaded and every drawn texture
// is sampled at the level the streamer wants. Every frame is checked for untextured objects.
Settled settle(SceneStreamer& streamer, SceneRenderer& renderer, const PerspectiveView& camera) {
  Settled out;
  for (; out.frames < 300; ++out.frames) {
    out.frame = streamer.update(camera);
    out.draw = renderer.draw(streamer, camera);
    EXPECT_EQ(out.frame.untextured_objects, 0u);
    EXPECT_EQ(out.draw.untextured_objects, 0u);
    if (out.frames > 0 && out.frame.reads_started == 0 && out.frame.results_applied == 0 &&
        out.draw.bytes_uploaded == 0 && out.draw.textures_below_wanted == 0)
      break;
    streamer.waitForReads();
  }
  return out;
}

TEST(SceneRenderer, PictureAtRestMatchesEveryTextureResident) {
  context();
  ScratchDir dir;
  std::shared_ptr<SceneArchive> archive = buildCity(dir);
  ASSERT_TRUE(archive);
  auto streamer = SceneStreamer::open(archive);
  ASSERT_TRUE(streamer.has_value()) << streamer.error().message;
  auto renderer = SceneRenderer::create(archive);
  ASSERT_TRUE(renderer.has_value()) << renderer.error().message;
  const PerspectiveView camera = streetLevel(archive->summary());
  const Settled settled = settle(**streamer, **renderer, camera);
  ASSERT_LT(settled.frames, 300);
  ASSERT_GT(settled.draw.objects_drawn, 3u);
  EXPECT_EQ(settled.draw.objects_drawn, (*streamer)->drawableObjects().size());
  const Picture streamed = (*renderer)->readPixels();

  SceneRenderOptions whole;
  whole.all_levels_resident = true;
  auto reference = SceneRenderer::create(archive, whole);
  ASSERT_TRUE(reference.has_value()) << reference.error().message;
  const SceneDrawStats drawn = (*reference)->draw(**streamer, camera);
  EXPECT_EQ((*reference)->readFailures(), 0u) << (*reference)->firstReadError();
  EXPECT_EQ(drawn.objects_drawn, settled.draw.objects_drawn);
  const Picture expected = (*reference)->readPixels();
  auto difference = comparePictures(streamed, expected);
  ASSERT_TRUE(difference.has_value());
  EXPECT_GE(difference->psnr_db, 40.0) << "max " << difference->max_abs;
  // The streamed textures are not all at level 0: the streamer keeps what the screen resolves.
  uint32_t coarser = 0;
  for (uint32_t t = 0; t < archive->summary().textures; ++t)
    if ((*renderer)->sampledLevel(t) > 0 && (*reference)->sampledLevel(t) == 0) ++coarser;
  EXPECT_GT(coarser, 0u);
}

TEST(SceneRenderer, NeverSamplesALevelThatHasNotArrived) {
  context();
  ScratchDir dir;
  std::shared_ptr<SceneArchive> archive = buildCity(dir);
  ASSERT_TRUE(archive);
  // A budget of one byte keeps every texture at its coarsest level.
  SceneStreamOptions stream;
  stream.moving_texel_budget_bytes = stream.still_texel_budget_bytes = 1;
  auto streamer = SceneStreamer::open(archive, stream);
  ASSERT_TRUE(streamer.has_value()) << streamer.error().message;
  // Two renderers whose levels start as two different pure colours: where either samples a
  // level that never arrived, their pictures differ.
  SceneRenderOptions magenta, green;
  magenta.unloaded_level_rgba = 0xFFFF00FFu;
  green.unloaded_level_rgba = 0xFF00FF00u;
  auto first = SceneRenderer::create(archive, magenta);
  auto second = SceneRenderer::create(archive, green);
  ASSERT_TRUE(first.has_value()) << first.error().message;
  ASSERT_TRUE(second.has_value()) << second.error().message;
  // A narrow field of view magnifies the facades: the sampler wants levels finer than the
  // coarsest.
  PerspectiveView camera = streetLevel(archive->summary());
  camera.fov_y_rad = 0.15;
  for (int frame = 0; frame < 20; ++frame) {
    (*streamer)->update(camera);
    (*first)->draw(**streamer, camera);
    (*second)->draw(**streamer, camera);
    (*streamer)->waitForReads();
  }
  const SceneFrameStats frame = (*streamer)->update(camera);
  const SceneDrawStats drawn = (*first)->draw(**streamer, camera);
  (*second)->draw(**streamer, camera);
  ASSERT_GT(drawn.objects_drawn, 0u);
  EXPECT_EQ(frame.untextured_objects, 0u);
  // The screen wants finer levels than arrived: without the clamp the sampler would take them.
  auto records = archive->textures(0, archive->summary().textures);
  ASSERT_TRUE(records.has_value());
  uint32_t clamped = 0;
  for (const SceneTexture& texture : *records) {
    const uint32_t sampled = (*first)->sampledLevel(texture.index);
    if (sampled < texture.info.level_count && sampled > (*streamer)->wantedLevel(texture.index))
      ++clamped;
  }
  EXPECT_GT(clamped, 0u);
  EXPECT_EQ(drawn.textures_below_wanted, clamped);
  auto difference = comparePictures((*first)->readPixels(), (*second)->readPixels());
  ASSERT_TRUE(difference.has_value());
  EXPECT_EQ(difference->max_abs, 0u);
}

TEST(SceneRenderer, UploadsAtMostOneFinerLevelAFrameUnderATinyBudget) {
  context();
  ScratchDir dir;
  std::shared_ptr<SceneArchive> archive = buildCity(dir);
  ASSERT_TRUE(archive);
  auto streamer = SceneStreamer::open(archive);
  ASSERT_TRUE(streamer.has_value()) << streamer.error().message;
  SceneRenderOptions options;
  options.upload_budget_bytes = 1;
  auto renderer = SceneRenderer::create(archive, options);
  ASSERT_TRUE(renderer.has_value()) << renderer.error().message;
  const PerspectiveView camera = streetLevel(archive->summary());
  uint32_t levels = 0;
  for (int frame = 0; frame < 300; ++frame) {
    (*streamer)->update(camera);
    const SceneDrawStats drawn = (*renderer)->draw(**streamer, camera);
    EXPECT_LE(drawn.levels_uploaded, 1u);
    levels += drawn.levels_uploaded;
    if (frame > 0 && drawn.textures_below_wanted == 0 && drawn.levels_uploaded == 0) break;
    (*streamer)->waitForReads();
  }
  EXPECT_GT(levels, 1u);  // the budget delays levels; it never loses them
}

}  // namespace
}  // namespace tessera
