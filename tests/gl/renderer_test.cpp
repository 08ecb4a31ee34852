// The OpenGL backend, headless on EGL's surfaceless platform (Mesa llvmpipe in CI): a real
// streamer feeds a real renderer; pictures are read back and checked texel by texel.
#include <algorithm>
#include <map>
#include <unordered_set>
#include <memory>

#include <gtest/gtest.h>

#include <tessera/build.h>
#include <tessera/gl.h>
#include <tessera/renderer.h>
#include <tessera/render.h>
#include <tessera/stream.h>

#include "gl/gl_objects.h"
#include "gl/renderers.h"
#include "gl_test_context.h"
#include "support/fault_source.h"
#include "support/synthetic_archive.h"
#include "support/test_images.h"

namespace tessera {
namespace {

GlContext& sharedContext() {
  return test::sharedGlContext();
}

View orthoAt(double x, double y, double texels_per_pixel, uint32_t w, uint32_t h) {
  View view;
  view.ortho.centre_x = x;
  view.ortho.centre_y = y;
  view.ortho.texels_per_pixel = texels_per_pixel;
  view.ortho.viewport_w = w;
  view.ortho.viewport_h = h;
  return view;
}

/// Level-0 texel (x, y) as a picture shows it (grey expanded, alpha 255 when absent).
std::array<uint8_t, 4> texelAt(const Archive& archive, uint32_t x, uint32_t y) {
  const ImageInfo& info = archive.images()[0];
  const uint32_t t = info.tile_size_px;
  auto tile = archive.readTile({0, 0, x / t, y / t});
  EXPECT_TRUE(tile) << tile.error().message;
  if (!tile) return {};
  const uint32_t side = info.storedTileSidePx(), c = info.channels;
  const uint8_t* p =
      tile->texels.data() + (size_t(y % t + info.border_px) * side + x % t + info.border_px) * c;
  switch (c) {
    case 1: return {p[0], p[0], p[0], 255};
    case 2: return {p[0], p[0], p[0], p[1]};
    case 3: return {p[0], p[1], p[2], 255};
    default: return {p[0], p[1], p[2], p[3]};
  }
}

struct Rig {
  std::shared_ptr<test::FaultSource> source;
  std::shared_ptr<Archive> archive;
  std::unique_ptr<TileStreamer> streamer;
  std::unique_ptr<Renderer> renderer;

  explicit Rig(const test::SyntheticArchiveSpec& spec, RendererKind kind,
               const RendererOptions& renderer_options = {}) {
    sharedContext();
    const std::vector<uint8_t>& bytes = test::syntheticArchiveBytes(spec);
    source = std::make_shared<test::FaultSource>(makeMemorySource(bytes, "mem:gl.tess"));
    archive = test::openArchiveOrFail(source);
    if (!archive) return;
    test::warmDirectory(*archive);
    // The renderer first, as the tools make them: it says whether bc tiles stay blocks.
    auto made = createRenderer(kind, archive->images()[0], renderer_options);
    EXPECT_TRUE(made) << made.error().message;
    if (made) renderer = std::move(*made);
    StreamerOptions options;
    options.cache_budget_bytes = size_t(256) << 20;
    options.loader_threads = 2;
    options.keep_block_compressed = renderer && renderer->takesStoredBlocks();
    auto created = TileStreamer::create(archive, options);
    EXPECT_TRUE(created) << created.error().message;
    if (created) streamer = std::move(*created);
  }

  // Loader threads held at a closed gate must get out before the streamer joins them.
  ~Rig() {
    if (source) source->openGate();
  }

  bool ready() const { return archive && streamer && renderer; }

  /// One frame as a viewer runs it.
  const FrameUpdate& frame(const View& view) {
    const FrameUpdate& update = streamer->update(view);
    streamer->acknowledge(renderer->apply(update));
    renderer->draw(view);
    return update;
  }

  /// Frames until two frames in a row found nothing loading or going up (the loader may
  /// finish tiles after a frame polled it; waiting for it between frames lets the next frame
  /// see them).
  void settle(const View& view) {
    int quiet = 0;
    for (int i = 0; i < 500; ++i) {
      const FrameUpdate& update = frame(view);
      // Tiles a renderer declines (a clipmap slot held by a tile of the clip region) are
      // offered every frame; they do not keep the view from settling.
      const bool idle = update.uploads.size() == renderer->stats().declined &&
                        update.report.queue_length == 0 && update.report.in_flight == 0;
      quiet = idle ? quiet + 1 : 0;
      if (quiet == 2) return;
      streamer->waitIdleForTesting();
    }
    ADD_FAILURE() << "the view never settled";
  }
};

class RendererChannels : public testing::TestWithParam<std::tuple<RendererKind, uint32_t>> {};

TEST_P(RendererChannels, AtOneTexelPerPixelTheScreenShowsLevelZeroTexelsExactly) {
  test::SyntheticArchiveSpec spec;
  spec.width_px = 500;  // odd sizes: the last column and row of tiles are partly padding
  spec.height_px = 371;
  spec.channels = std::get<1>(GetParam());
  spec.codec = Codec::kPng;
  spec.border_px = 1;
  Rig rig(spec, std::get<0>(GetParam()));
  ASSERT_TRUE(rig.ready());
  // Centre on a whole texel so pixel centres fall on texel centres; the view crosses tile
  // edges (every 64 px) and the image's right and bottom edges.
  const View view = orthoAt(450, 330, 1, 96, 80);
  rig.settle(view);
  Picture picture = rig.renderer->readPixels();
  ASSERT_EQ(picture.width, 96u);
  ASSERT_EQ(picture.height, 80u);
  uint32_t worst = 0, outside_nonzero = 0;
  for (uint32_t py = 0; py < picture.height; ++py) {
    for (uint32_t px = 0; px < picture.width; ++px) {
      const int64_t x = 450 - 48 + int64_t(px), y = 330 - 40 + int64_t(py);
      const uint8_t* got = &picture.rgba[(size_t(py) * picture.width + px) * 4];
      if (x >= int64_t(spec.width_px) || y >= int64_t(spec.height_px)) {
        outside_nonzero += got[0] | got[1] | got[2] | got[3];  // beyond the image: transparent
        continue;
      }
      const auto want = texelAt(*rig.archive, uint32_t(x), uint32_t(y));
      for (int c = 0; c < 4; ++c)
        worst = std::max<uint32_t>(worst, uint32_t(std::abs(int(got[c]) - int(want[size_t(c)]))));
    }
  }
  EXPECT_LE(worst, 1u) << "largest channel difference from the level-0 texels";
  EXPECT_EQ(outside_nonzero, 0u);
  EXPECT_GT(rig.renderer->stats().tiles_drawn, 0u);
  if (std::get<0>(GetParam()) == RendererKind::kTileQuads) {
    // The 96 x 80 view meets at most 3 x 3 level-0 tiles; every coarser tile there is hidden
    // under resident children, or drawn only where the image's edge leaves it childless.
    EXPECT_LE(rig.renderer->stats().tiles_drawn, 9u + 2u);
  }
}

std::string kindName(RendererKind kind) {
  return kind == RendererKind::kTileQuads ? "TileQuads" : "Clipmap";
}

INSTANTIATE_TEST_SUITE_P(
    All, RendererChannels,
    testing::Combine(testing::Values(RendererKind::kTileQuads, RendererKind::kClipmap),
                     testing::Values(1u, 2u, 3u, 4u)),
    [](const testing::TestParamInfo<std::tuple<RendererKind, uint32_t>>& param_info) {
      return kindName(std::get<0>(param_info.param)) + "_" +
             std::to_string(std::get<1>(param_info.param)) + "ch";
    });

class Renderers : public testing::TestWithParam<RendererKind> {};

TEST_P(Renderers, TheRenderLoopNeverWaitsForAStalledSource) {
  test::SyntheticArchiveSpec spec;
  spec.border_px = 1;
  Rig rig(spec, GetParam());
  ASSERT_TRUE(rig.ready());
  const ImageInfo& info = rig.archive->images()[0];
  rig.settle(orthoAt(200, 200, 1, 128, 96));
  // Every read now blocks; the view jumps to the other corner, whose level-0 tiles were
  // never loaded.
  rig.source->closeGate();
  const View far_view = orthoAt(info.width_px - 100.0, info.height_px - 100.0, 1, 128, 96);
  FrameReport last{};
  for (int i = 0; i < 30; ++i) last = rig.frame(far_view).report;
  EXPECT_TRUE(rig.source->waitUntilBlocked(1)) << "the loader never reached the stalled read";
  EXPECT_LT(last.coverage_desired, 1.0);  // level 0 could not arrive
  EXPECT_TRUE(last.fully_covered);        // a coarser level covers the screen meanwhile
  Picture picture = rig.renderer->readPixels();
  size_t transparent = 0;
  for (size_t i = 3; i < picture.rgba.size(); i += 4) transparent += picture.rgba[i] == 0;
  EXPECT_EQ(transparent, 0u) << "pixels of the image left uncovered while the source stalls";
  rig.source->openGate();
}

TEST_P(Renderers, ReleasedTilesLeaveTheGpuAndTheirRoomIsReused) {
  test::SyntheticArchiveSpec spec;
  spec.border_px = 1;
  Rig rig(spec, GetParam());
  ASSERT_TRUE(rig.ready());
  const ImageInfo& info = rig.archive->images()[0];
  const View near_view = orthoAt(100, 100, 1, 128, 96);
  rig.settle(near_view);
  const TileId corner{0, 0, 0, 0};
  ASSERT_TRUE(rig.renderer->resident(corner));
  const uint64_t gpu_bytes = rig.renderer->stats().gpu_bytes;
  // Back and forth across the image: tiles left behind are released and their layers taken
  // by the new ones, so texture memory stops growing.
  for (int round = 0; round < 3; ++round) {
    rig.settle(orthoAt(info.width_px - 100.0, info.height_px - 100.0, 1, 128, 96));
    EXPECT_FALSE(rig.renderer->resident(corner));
    rig.settle(near_view);
    EXPECT_TRUE(rig.renderer->resident(corner));
  }
  EXPECT_LE(rig.renderer->stats().gpu_bytes, 2 * gpu_bytes);
  EXPECT_EQ(rig.renderer->stats().resident_tiles, [&] {
    uint32_t resident = 0;
    for (const TileId& id : test::allTiles(*rig.archive))
      resident += rig.streamer->state(id) == TileState::kResident ||
                  rig.streamer->state(id) == TileState::kLocked;
    return resident;
  }());
}

struct NamedView {
  const char* name;
  View view;
};

std::vector<NamedView> restViews() {
  std::vector<NamedView> views;
  auto ortho = [&](const char* name, double x, double y, double tpp, double rotation = 0) {
    View view = orthoAt(x, y, tpp, 160, 120);
    view.ortho.rotation_rad = rotation;
    views.push_back({name, view});
  };
  ortho("inside, between texels", 300.3, 200.7, 1);
  ortho("tile corner, between levels 0 and 1", 256, 192, 1.5);
  ortho("image corner", 1000, 760, 1);
  ortho("magnified 8x", 517.2, 333.9, 0.125);
  ortho("whole image, coarse levels", 512, 384, 8);
  ortho("rotated, levels 1 and 2", 600, 400, 2.6, 0.6);
  View perspective;
  perspective.kind = View::Kind::kPerspective;
  perspective.perspective = {480, 700, 180, 0.4, -0.55, 1.0, 160, 120};
  views.push_back({"perspective, yawed", perspective});
  return views;
}

TEST_P(Renderers, AtRestTheyMatchTheReferenceOnALosslessArchive) {
  for (uint32_t border : {0u, 1u}) {
    SCOPED_TRACE(border);
    test::SyntheticArchiveSpec spec;
    spec.codec = Codec::kPng;
    spec.border_px = border;
    Rig rig(spec, GetParam());
    ASSERT_TRUE(rig.ready());
    for (const NamedView& named : restViews()) {
      SCOPED_TRACE(named.name);
      rig.settle(named.view);
      rig.frame(named.view);
      Picture gpu = rig.renderer->readPixels();
      ReferenceOptions options;
      options.available = [&](const TileId& id) { return rig.renderer->resident(id); };
      auto reference = renderReference(*rig.archive, named.view, options);
      ASSERT_TRUE(reference) << reference.error().message;
      auto difference = comparePictures(gpu, *reference);
      ASSERT_TRUE(difference) << difference.error().message;
      EXPECT_GE(difference->psnr_db, 45.0) << "max difference " << difference->max_abs;
      // Not trivially equal: the view shows texture, not a cleared screen.
      size_t opaque = 0;
      for (size_t i = 3; i < gpu.rgba.size(); i += 4) opaque += gpu.rgba[i] == 255;
      EXPECT_GT(opaque, gpu.rgba.size() / 16);
    }
  }
}

/// An archive whose 64-px tiles are each one flat colour, unlike their neighbours: any texel
/// a renderer takes from the wrong tile, or any edge it clamps instead of filtering across,
/// shows as a seam.
std::shared_ptr<Archive> checkerArchive(uint32_t border_px, Codec codec = Codec::kPng) {
  static std::map<std::pair<uint32_t, Codec>, std::vector<uint8_t>> built;
  auto& bytes = built[{border_px, codec}];
  if (bytes.empty())
    bytes = [border_px, codec] {
      const uint32_t w = 512, h = 384, t = 64;
      std::vector<uint8_t> pixels(size_t(w) * h * 3);
      for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x) {
          const uint32_t tile = (y / t) * 97 + (x / t) * 31;
          uint8_t* p = &pixels[(size_t(y) * w + x) * 3];
          p[0] = uint8_t((tile * 73) % 256);
          p[1] = uint8_t((tile * 151 + 80) % 256);
          p[2] = uint8_t(((x / t + y / t) % 2) * 200 + 20);
        }
      const std::string dir = test::testTempDir();
      test::PngSpec png;
      png.width_px = w;
      png.height_px = h;
      const std::string input = dir + "checker.png", output = dir + "checker-" +
                                                              std::to_string(border_px) + "-" +
                                                              codecName(codec) + ".tess";
      EXPECT_EQ(test::writePng(input, png, pixels), "");
      BuildOptions options;
      options.inputs = {input};
      options.output = output;
      options.tile_size_px = t;
      options.border_px = border_px;
      options.codec = codec;
      auto report = buildArchive(options);
      EXPECT_TRUE(report) << report.error().message;
      return test::readFileBytes(output);
    }();
  return test::openArchiveOrFail(makeMemorySource(bytes, "mem:checker.tess"));
}

TEST_P(Renderers, TileEdgesShowNoSeamsMagnifiedOrMinified) {
  sharedContext();
  // With borders the tile quads filter inside each tile; without, across tiles from their
  // resident neighbours; the clipmap needs no borders either way.
  for (uint32_t border : {0u, 1u}) {
    SCOPED_TRACE(border);
    std::shared_ptr<Archive> archive = checkerArchive(border);
    ASSERT_TRUE(archive);
    StreamerOptions options;
    options.loader_threads = 2;
    auto streamer = TileStreamer::create(archive, options);
    auto renderer = createRenderer(GetParam(), archive->images()[0]);
    ASSERT_TRUE(streamer && renderer);
    for (double tpp : {0.25, 0.6, 1.0, 2.5, 3.7}) {
      SCOPED_TRACE(tpp);
      // Centred on a corner where four tiles meet (and at the coarser levels too).
      const View view = orthoAt(256.3, 192.4, tpp, 160, 120);
      for (int i = 0; i < 200; ++i) {
        const FrameUpdate& update = (*streamer)->update(view);
        (*streamer)->acknowledge((*renderer)->apply(update));
        if (update.uploads.empty() && update.report.queue_length == 0 &&
            update.report.in_flight == 0 && update.report.coverage_desired >= 1 && i > 2)
          break;
        (*streamer)->waitIdleForTesting();
      }
      (*renderer)->draw(view);
      Picture gpu = (*renderer)->readPixels();
      ReferenceOptions reference_options;
      reference_options.available = [&](const TileId& id) { return (*renderer)->resident(id); };
      auto reference = renderReference(*archive, view, reference_options);
      ASSERT_TRUE(reference);
      auto difference = comparePictures(gpu, *reference);
      ASSERT_TRUE(difference);
      // A seam is a whole row or column of texels off by up to half the colour step (~100).
      EXPECT_LE(difference->max_abs, 6u);
      EXPECT_GE(difference->psnr_db, 45.0);
    }
  }
}

TEST_P(Renderers, AFastPanNeverUncoversThePictureAndEachFrameMatchesItsResidentLevels) {
  test::SyntheticArchiveSpec spec;
  spec.codec = Codec::kPng;
  spec.border_px = 1;
  Rig rig(spec, GetParam());
  ASSERT_TRUE(rig.ready());
  rig.settle(orthoAt(100, 100, 1, 160, 120));
  // The reference reads the same bytes through a source that never stalls.
  std::shared_ptr<Archive> clean = test::openArchiveOrFail(
      makeMemorySource(test::syntheticArchiveBytes(spec), "mem:clean.tess"));
  ASSERT_TRUE(clean);
  // 72 px a frame diagonally, never waiting for the loader, whose reads stall for the first
  // seven frames: frames show whatever is resident, coarser levels where the finest has not
  // arrived.
  size_t frames_below_full_detail = 0;
  rig.source->closeGate();
  for (int k = 1; k <= 14; ++k) {
    SCOPED_TRACE(k);
    if (k == 8) rig.source->openGate();
    const View view = orthoAt(100 + 60.0 * k, 100 + 40.0 * k, 1, 160, 120);
    const FrameReport report = rig.frame(view).report;
    frames_below_full_detail += report.coverage_desired < 1;
    EXPECT_TRUE(report.fully_covered);
    Picture gpu = rig.renderer->readPixels();
    for (size_t i = 3; i < gpu.rgba.size(); i += 4)
      ASSERT_EQ(gpu.rgba[i], 255) << "an uncovered pixel at " << i / 4;
    ReferenceOptions options;
    options.available = [&](const TileId& id) { return rig.renderer->resident(id); };
    auto reference = renderReference(*clean, view, options);
    ASSERT_TRUE(reference);
    auto difference = comparePictures(gpu, *reference);
    ASSERT_TRUE(difference);
    // 40 dB, not the 45 at rest: while tiles are missing, the clipmap skips the trilinear
    // blend where the coarser level's bilinear footprint reaches a tile it does not hold (a
    // parent's neighbour), which the reference, like the tile quads and their parent borders,
    // blends; those strips differ by a fraction of a level's detail.
    EXPECT_GE(difference->psnr_db, 40.0);
  }
  // The fallback was exercised.
  EXPECT_GT(frames_below_full_detail, 0u);
  rig.source->openGate();
}

TEST_P(Renderers, ApplyAnswersForEveryUploadAndHoldsWhatItAccepted) {
  test::SyntheticArchiveSpec spec;
  spec.border_px = 1;
  Rig rig(spec, GetParam());
  ASSERT_TRUE(rig.ready());
  const ImageInfo& info = rig.archive->images()[0];
  // A pan across the image and back: uploads, releases, and for the clipmap slots that wrap.
  size_t accepted = 0;
  for (int i = 0; i < 60; ++i) {
    const double x = 100 + (info.width_px - 200.0) * (i < 30 ? i : 59 - i) / 29.0;
    const View view = orthoAt(x, info.height_px / 2.0, 1, 128, 96);
    const FrameUpdate& update = rig.streamer->update(view);
    std::unordered_set<TileId, TileIdHash> uploads;
    for (const auto& tile : update.uploads) uploads.insert(tile->id);
    std::unordered_set<TileId, TileIdHash> held_before;
    for (const TileId& id : test::allTiles(*rig.archive))
      if (rig.renderer->resident(id)) held_before.insert(id);
    const ApplyResult& result = rig.renderer->apply(update);
    // Each upload is accepted or declined, never both, and nothing else is.
    std::unordered_set<TileId, TileIdHash> answered(result.accepted.begin(), result.accepted.end());
    for (const TileId& id : result.declined) EXPECT_TRUE(answered.insert(id).second);
    EXPECT_EQ(answered, uploads);
    for (const TileId& id : result.accepted) EXPECT_TRUE(rig.renderer->resident(id));
    for (const TileId& id : result.declined) EXPECT_FALSE(rig.renderer->resident(id));
    // Dropped tiles were held before this frame and are not any more.
    for (const TileId& id : result.dropped) {
      EXPECT_TRUE(held_before.count(id));
      EXPECT_FALSE(rig.renderer->resident(id));
    }
    EXPECT_EQ(rig.renderer->stats().uploads, result.accepted.size());
    EXPECT_EQ(rig.renderer->stats().declined, result.declined.size());
    accepted += result.accepted.size();
    rig.streamer->acknowledge(result);
    rig.renderer->draw(view);
    rig.streamer->waitIdleForTesting();
  }
  EXPECT_GT(accepted, 0u);
}

// The staging ring (src/gl/upload_ring.h) on the real driver: a ring of a tile and a half
// takes one tile a frame and declines the rest at once (never waiting for the GPU), the
// declined tiles go up in later frames, and the picture at rest is the one a renderer with
// the default ring draws.
TEST_P(Renderers, AFullStagingRingDeclinesUploadsAndTheyGoUpLater) {
  test::SyntheticArchiveSpec spec;
  spec.border_px = 1;
  Rig roomy(spec, GetParam());
  RendererOptions tight;
  tight.staging_ring_bytes = spec.tile_size_px * spec.tile_size_px * 4 * 3 / 2;
  Rig cramped(spec, GetParam(), tight);
  ASSERT_TRUE(roomy.ready() && cramped.ready());
  const ImageInfo& info = cramped.archive->images()[0];
  const View view = orthoAt(info.width_px / 2.0, info.height_px / 2.0, 1, 160, 120);
  size_t most_accepted = 0, declined = 0;
  for (int i = 0; i < 200; ++i) {
    const FrameUpdate& update = cramped.streamer->update(view);
    const ApplyResult& result = cramped.renderer->apply(update);
    most_accepted = std::max(most_accepted, result.accepted.size());
    declined += result.declined.size();
    cramped.streamer->acknowledge(result);
    cramped.renderer->draw(view);
    const bool idle =
        update.uploads.empty() && update.report.queue_length == 0 && update.report.in_flight == 0;
    if (idle && i > 2) break;
    (void)cramped.renderer->readPixels();  // the test waits for the GPU; a renderer never does
    cramped.streamer->waitIdleForTesting();
  }
  EXPECT_EQ(most_accepted, 1u) << "one tile fits the ring a frame";
  EXPECT_GT(declined, 0u);
  roomy.settle(view);
  const Picture a = roomy.renderer->readPixels(), b = cramped.renderer->readPixels();
  auto difference = comparePictures(a, b);
  ASSERT_TRUE(difference) << difference.error().message;
  EXPECT_EQ(difference->max_abs, 0u);
}

TEST(TileQuads, TheTileArrayIsSizedFromTheResidencyBoundAtTheFirstFrameAndNeverGrowsInAPan) {
  test::SyntheticArchiveSpec spec;
  spec.border_px = 1;
  Rig rig(spec, RendererKind::kTileQuads);
  ASSERT_TRUE(rig.ready());
  const ImageInfo& info = rig.archive->images()[0];
  const View first = orthoAt(100, info.height_px / 2.0, 1, 128, 96);
  const uint64_t bound = rig.frame(first).resident_tiles_bound;
  ASSERT_GT(bound, RendererOptions{}.initial_layers) << "the test needs a bound above the default";
  const uint64_t sized = rig.renderer->stats().gpu_bytes;
  EXPECT_EQ(sized, bound * info.storedTileBytes());
  for (int i = 0; i < 40; ++i) {
    rig.streamer->waitIdleForTesting();
    rig.frame(orthoAt(100 + (info.width_px - 200.0) * i / 39.0, info.height_px / 2.0, 1, 128, 96));
    EXPECT_LE(rig.renderer->stats().resident_tiles, bound);
    EXPECT_EQ(rig.renderer->stats().gpu_bytes, sized) << "frame " << i;
  }
}

class SizedUpFront : public testing::TestWithParam<RendererKind> {};

TEST_P(SizedUpFront, StorageIsAllocatedAtCreationAndNoFrameOfAPanAllocates) {
  test::SyntheticArchiveSpec spec;
  spec.border_px = 1;
  Rig rig(spec, GetParam());
  ASSERT_TRUE(rig.ready());
  const ImageInfo& info = rig.archive->images()[0];
  const View first = orthoAt(100, info.height_px / 2.0, 1, 128, 96);
  // Left to size itself, a renderer allocates during its first frames.
  const RenderStats lazy_before = rig.renderer->stats();
  rig.frame(first);
  rig.streamer->waitIdleForTesting();
  rig.frame(first);
  EXPECT_GT(rig.renderer->stats().storage_allocations, lazy_before.storage_allocations);
  EXPECT_GT(rig.renderer->stats().gpu_bytes, lazy_before.gpu_bytes) << "tile storage grew";
  // Sized as `tessera fly` sizes it, before its clock starts.
  RendererOptions sized;
  sized.initial_layers = uint32_t(residentTilesBound(info, 128, 96, StreamerOptions{}.residency));
  sized.initial_clip_tiles = clipRegionTiles(128, 96, info.tile_size_px);
  auto made = createRenderer(GetParam(), info, sized);
  ASSERT_TRUE(made) << made.error().message;
  rig.renderer = std::move(*made);
  EXPECT_GT(rig.renderer->stats().gpu_bytes, 0u) << "tile storage allocated at creation";
  if (GetParam() == RendererKind::kTileQuads) {
    EXPECT_EQ(rig.renderer->stats().gpu_bytes, sized.initial_layers * info.storedTileBytes());
  }
  rig.renderer->draw(first);  // makes the colour target, as FlyRenderer::create does
  const uint32_t allocated = rig.renderer->stats().storage_allocations;
  EXPECT_GE(allocated, 3u) << "tile storage, staging ring and colour target";
  // The streamer still thinks the first renderer holds its tiles: a fresh streamer.
  StreamerOptions options;
  options.cache_budget_bytes = size_t(256) << 20;
  options.loader_threads = 2;
  auto streamer = TileStreamer::create(rig.archive, options);
  ASSERT_TRUE(streamer) << streamer.error().message;
  rig.streamer = std::move(*streamer);
  uint32_t most_resident = 0;
  for (int i = 0; i < 30; ++i) {
    rig.frame(orthoAt(100 + (info.width_px - 200.0) * i / 29.0, info.height_px / 2.0, 1, 128, 96));
    EXPECT_EQ(rig.renderer->stats().storage_allocations, allocated) << "frame " << i;
    most_resident = std::max(most_resident, rig.renderer->stats().resident_tiles);
    rig.streamer->waitIdleForTesting();
  }
  EXPECT_GT(most_resident, 1u) << "the pan uploaded tiles";
}

INSTANTIATE_TEST_SUITE_P(Renderers, SizedUpFront,
                         testing::Values(RendererKind::kTileQuads, RendererKind::kClipmap),
                         [](const testing::TestParamInfo<RendererKind>& param_info) {
                           return std::string(param_info.param == RendererKind::kTileQuads
                                                  ? "TileQuads"
                                                  : "Clipmap");
                         });

/// Why the current context cannot sample `codec`'s blocks; empty when it can.
std::string blockFormatMissing(Codec codec) {
  sharedContext();
  if (gl::blockInternalFormat(codec) != 0) return "";
  return codec == Codec::kBc1 ? "the GL driver offers no S3TC (BC1) textures"
                              : "the GL driver offers no BPTC (BC7) textures";
}

class BlockTiles : public testing::TestWithParam<std::tuple<Codec, uint32_t, uint32_t>> {};

// bc tiles go up as stored (no CPU decode, a quarter or an eighth of the bytes), in layers
// padded to whole blocks when the bordered side (66 px) is not a multiple of 4, and the picture
// shows the texels the CPU decoder gives the reference renderer: no seam, no uncovered pixel.
TEST_P(BlockTiles, GoUpAsStoredAndDrawTheReferencesDecodedTexels) {
  const auto [codec, channels, border] = GetParam();
  if (std::string missing = blockFormatMissing(codec); !missing.empty()) GTEST_SKIP() << missing;
  test::SyntheticArchiveSpec spec;
  spec.width_px = 300;  // odd sizes: the last column and row of tiles are partly padding
  spec.height_px = 220;
  spec.channels = channels;
  spec.codec = codec;
  spec.border_px = border;
  Rig rig(spec, RendererKind::kTileQuads);
  ASSERT_TRUE(rig.ready());
  ASSERT_TRUE(rig.renderer->takesStoredBlocks());
  const ImageInfo& info = rig.archive->images()[0];
  const size_t blocks_along = (info.storedTileSidePx() + 3) / 4;
  const size_t block_tile_bytes = blocks_along * blocks_along * (codec == Codec::kBc1 ? 8 : 16);
  // Pixel centres on texel centres show the texels themselves: bc7 decodes exactly as the CPU
  // does, bc1 within a level (docs/codecs.md). Between texels the driver's bilinear filter
  // adds its rounding: on llvmpipe, up to 4 levels at the sharpest edges of the synthetic
  // image when it filters a block layer (bordered tiles), 1 on an RGBA layer.
  const uint32_t on_texels = codec == Codec::kBc1 ? 1 : 0;
  const uint32_t filtered = border > 0 ? 4 : 1 + on_texels;
  struct NamedBlockView {
    const char* name;
    View view;
    uint32_t max_abs;
  };
  const NamedBlockView views[] = {
      {"on texel centres, across tile edges", orthoAt(130, 100, 1, 96, 72), on_texels},
      {"image corner", orthoAt(280, 200, 1, 64, 48), on_texels},
      {"between texels", orthoAt(130.3, 100.7, 1, 96, 72), filtered},
      {"magnified 4x on a tile corner", orthoAt(128.2, 64.9, 0.25, 64, 48), filtered},
      {"between levels 0 and 1", orthoAt(150, 110, 1.5, 96, 72), filtered},
      {"whole image, coarse levels", orthoAt(152, 112, 4, 80, 60), filtered},
  };
  size_t block_tiles = 0;
  for (const NamedBlockView& named : views) {
    SCOPED_TRACE(named.name);
    // Every accepted upload is as many bytes as the stats say, and a kept tile is its blocks.
    for (int i = 0; i < 200; ++i) {
      const FrameUpdate& update = rig.frame(named.view);
      uint64_t offered_bytes = 0;
      for (const auto& tile : update.uploads) {
        offered_bytes += tile->uploadBytes().size();
        if (!tile->keptAsBlocks()) continue;
        ++block_tiles;
        EXPECT_TRUE(tile->texels.texels.empty());
        EXPECT_EQ(tile->blocks.bytes.size(), block_tile_bytes);
      }
      if (rig.renderer->stats().declined == 0) {
        EXPECT_EQ(rig.renderer->stats().upload_bytes, offered_bytes);
      }
      if (update.report.queue_length == 0 && update.report.in_flight == 0 && update.uploads.empty())
        break;
      rig.streamer->waitIdleForTesting();
    }
    rig.settle(named.view);
    rig.frame(named.view);
    Picture gpu = rig.renderer->readPixels();
    ReferenceOptions options;
    options.available = [&](const TileId& id) { return rig.renderer->resident(id); };
    auto reference = renderReference(*rig.archive, named.view, options);
    ASSERT_TRUE(reference) << reference.error().message;
    auto difference = comparePictures(gpu, *reference);
    ASSERT_TRUE(difference) << difference.error().message;
    EXPECT_LE(difference->max_abs, named.max_abs);
    EXPECT_GE(difference->psnr_db, 54.0);
    // No uncovered pixel: inside the image every pixel is drawn (alpha as the reference has it).
    size_t gpu_transparent = 0, reference_transparent = 0;
    for (size_t i = 3; i < gpu.rgba.size(); i += 4) {
      gpu_transparent += gpu.rgba[i] == 0;
      reference_transparent += reference->rgba[i] == 0;
    }
    EXPECT_EQ(gpu_transparent, reference_transparent);
  }
  EXPECT_GT(block_tiles, 0u) << "no tile went up as blocks";
}

// A flat 64-px tile is stored as a uniform entry, which has no blocks: it goes up decoded, into
// the RGBA array beside the block array. Borderless, level 0 is all such tiles and level 1 all
// blocks (each of its tiles spans four cells), so a view between the two levels blends texels
// of both arrays, and a tile's neighbours lend texels across its edges from either.
TEST(TileQuads, UniformTilesBesideBlockTilesShowNoSeams) {
  if (std::string missing = blockFormatMissing(Codec::kBc7); !missing.empty())
    GTEST_SKIP() << missing;
  std::shared_ptr<Archive> archive = checkerArchive(0, Codec::kBc7);
  ASSERT_TRUE(archive);
  auto renderer = createRenderer(RendererKind::kTileQuads, archive->images()[0]);
  ASSERT_TRUE(renderer);
  ASSERT_TRUE((*renderer)->takesStoredBlocks());
  StreamerOptions options;
  options.loader_threads = 2;
  options.keep_block_compressed = true;
  auto streamer = TileStreamer::create(archive, options);
  ASSERT_TRUE(streamer);
  size_t as_blocks = 0, decoded = 0;
  for (double tpp : {0.6, 1.5, 2.5}) {
    SCOPED_TRACE(tpp);
    const View view = orthoAt(256.3, 192.4, tpp, 128, 96);
    for (int i = 0; i < 200; ++i) {
      const FrameUpdate& update = (*streamer)->update(view);
      for (const auto& tile : update.uploads) ++(tile->keptAsBlocks() ? as_blocks : decoded);
      (*streamer)->acknowledge((*renderer)->apply(update));
      if (update.uploads.empty() && update.report.queue_length == 0 &&
          update.report.in_flight == 0 && update.report.coverage_desired >= 1 && i > 2)
        break;
      (*streamer)->waitIdleForTesting();
    }
    (*renderer)->draw(view);
    Picture gpu = (*renderer)->readPixels();
    ReferenceOptions reference_options;
    reference_options.available = [&](const TileId& id) { return (*renderer)->resident(id); };
    auto reference = renderReference(*archive, view, reference_options);
    ASSERT_TRUE(reference);
    auto difference = comparePictures(gpu, *reference);
    ASSERT_TRUE(difference);
    // A seam, or a layer read from the wrong array, is a row of texels off by ~100.
    EXPECT_LE(difference->max_abs, 2u);
    EXPECT_GE(difference->psnr_db, 54.0);
  }
  EXPECT_GT(as_blocks, 0u);
  EXPECT_GT(decoded, 0u);
}

// A JPEG archive streamed with transcode_to_bc1 goes up as bc1 blocks (an eighth of RGBA's
// upload and GPU bytes) into the renderer's bc1 array, and the picture is the JPEG reference's
// within the fast encoder's error; grey JPEG as well, through the one-channel swizzle.
TEST(TileQuads, TranscodedJpegTilesGoUpAsBc1) {
  if (std::string missing = blockFormatMissing(Codec::kBc1); !missing.empty())
    GTEST_SKIP() << missing;
  for (uint32_t channels : {3u, 1u}) {
    SCOPED_TRACE(channels);
    test::SyntheticArchiveSpec spec;
    spec.width_px = 300;
    spec.height_px = 220;
    spec.channels = channels;
    spec.codec = Codec::kJpeg;
    spec.border_px = 1;
    std::shared_ptr<Archive> archive = test::openArchiveOrFail(
        makeMemorySource(test::syntheticArchiveBytes(spec), "mem:jpeg.tess"));
    ASSERT_TRUE(archive);
    const ImageInfo& info = archive->images()[0];
    RendererOptions renderer_options;
    renderer_options.transcode_to_bc1 = true;
    auto renderer = createRenderer(RendererKind::kTileQuads, info, renderer_options);
    ASSERT_TRUE(renderer) << renderer.error().message;
    ASSERT_TRUE((*renderer)->takesStoredBlocks());
    auto plain = createRenderer(RendererKind::kTileQuads, info);
    ASSERT_TRUE(plain);
    EXPECT_FALSE((*plain)->takesStoredBlocks());
    StreamerOptions options;
    options.loader_threads = 2;
    options.transcode_to_bc1 = true;
    auto streamer = TileStreamer::create(archive, options);
    ASSERT_TRUE(streamer);
    const size_t padded = (info.storedTileSidePx() + 3) / 4 * 4;
    const View view = orthoAt(150.3, 110.6, 1.5, 96, 72);
    size_t as_blocks = 0;
    for (int i = 0; i < 200; ++i) {
      const FrameUpdate& update = (*streamer)->update(view);
      uint64_t offered_bytes = 0;
      for (const auto& tile : update.uploads) {
        offered_bytes += tile->uploadBytes().size();
        if (!tile->keptAsBlocks()) continue;
        ++as_blocks;
        EXPECT_EQ(tile->blocks.codec, Codec::kBc1);
        EXPECT_EQ(tile->uploadBytes().size() * 8, padded * padded * 4);
      }
      (*streamer)->acknowledge((*renderer)->apply(update));
      if ((*renderer)->stats().declined == 0) {
        EXPECT_EQ((*renderer)->stats().upload_bytes, offered_bytes);
      }
      if (update.uploads.empty() && update.report.queue_length == 0 &&
          update.report.in_flight == 0 && update.report.coverage_desired >= 1 && i > 2)
        break;
      (*streamer)->waitIdleForTesting();
    }
    EXPECT_GT(as_blocks, 0u);
    (*renderer)->draw(view);
    Picture gpu = (*renderer)->readPixels();
    ReferenceOptions reference_options;
    reference_options.available = [&](const TileId& id) { return (*renderer)->resident(id); };
    auto reference = renderReference(*archive, view, reference_options);
    ASSERT_TRUE(reference);
    auto difference = comparePictures(gpu, *reference);
    ASSERT_TRUE(difference);
    // Issue 30's floor for a load-time transcode; 40.5 dB (RGB) and 44.9 dB (grey) here.
    EXPECT_GE(difference->psnr_db, 33.0);
  }
}

INSTANTIATE_TEST_SUITE_P(
    All, BlockTiles,
    testing::Values(std::make_tuple(Codec::kBc1, 3u, 1u), std::make_tuple(Codec::kBc1, 3u, 0u),
                    std::make_tuple(Codec::kBc7, 4u, 1u), std::make_tuple(Codec::kBc7, 3u, 0u)),
    [](const testing::TestParamInfo<std::tuple<Codec, uint32_t, uint32_t>>& param_info) {
      return std::string(codecName(std::get<0>(param_info.param))) + "_" +
             std::to_string(std::get<1>(param_info.param)) + "ch_border" +
             std::to_string(std::get<2>(param_info.param));
    });

TEST(Clipmap, AfterAMoveEachLayerHoldsWhatAFreshUploadOfTheNewRegionHolds) {
  test::SyntheticArchiveSpec spec;
  spec.border_px = 1;
  Rig rig(spec, RendererKind::kClipmap);
  ASSERT_TRUE(rig.ready());
  // 128 x 96 px over 64-px tiles: n = 4 slots a side. Moving 6 tiles right and 4 down in
  // steps wraps the region around the layer, so tiles land in slots other tiles held.
  View view;
  for (int step = 0; step <= 8; ++step) {
    view = orthoAt(200 + step * 48.0, 150 + step * 32.0, 1, 128, 96);
    rig.settle(view);
  }
  const FrameUpdate& update = rig.frame(view);
  const uint32_t t = spec.tile_size_px, c = spec.channels, b = spec.border_px;
  for (uint32_t level : {0u, 1u}) {
    SCOPED_TRACE(level);
    auto layer = gl::readClipmapLayer(*rig.renderer, level);
    ASSERT_TRUE(layer) << layer.error().message;
    const uint32_t n = layer->slots;
    // Every tile of the level's clip region is in its slot (x mod n, y mod n)...
    TileRect region;
    for (const auto& r : update.regions)
      if (r.level == level) region = r.region;
    ASSERT_FALSE(region.empty());
    size_t wrapped = 0;
    for (int64_t y = region.y0; y < region.y1; ++y) {
      for (int64_t x = region.x0; x < region.x1; ++x) {
        const TileId id{0, level, uint32_t(x), uint32_t(y)};
        const uint32_t slot = uint32_t(y % n) * n + uint32_t(x % n);
        ASSERT_TRUE(layer->owners[slot].has_value()) << "tile " << x << "," << y << " missing";
        EXPECT_EQ(*layer->owners[slot], id);
        wrapped += x >= int64_t(n) || y >= int64_t(n);
      }
    }
    if (level == 0) {
      EXPECT_GT(wrapped, 0u) << "the move never wrapped around the layer";
    }
    // ...and every slot holds exactly its owner's texels, as a fresh upload would write them.
    size_t compared = 0;
    for (uint32_t slot = 0; slot < layer->owners.size(); ++slot) {
      if (!layer->owners[slot]) continue;
      auto tile = rig.archive->readTile(*layer->owners[slot]);
      ASSERT_TRUE(tile) << tile.error().message;
      const uint32_t stored = t + 2 * b, x0 = (slot % n) * t, y0 = (slot / n) * t;
      for (uint32_t y = 0; y < t; ++y) {
        const uint8_t* want = tile->texels.data() + (size_t(y + b) * stored + b) * c;
        const uint8_t* got = layer->texels.data() + (size_t(y0 + y) * layer->side + x0) * c;
        ASSERT_TRUE(std::equal(want, want + size_t(t) * c, got))
            << "slot " << slot << " row " << y << " differs from its tile";
      }
      ++compared;
    }
    EXPECT_GE(compared, size_t(region.count()));
  }
}

INSTANTIATE_TEST_SUITE_P(All, Renderers,
                         testing::Values(RendererKind::kTileQuads, RendererKind::kClipmap),
                         [](const testing::TestParamInfo<RendererKind>& param_info) {
                           return kindName(param_info.param);
                         });

}  // namespace
}  // namespace tessera
