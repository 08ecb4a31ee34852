// 16-bit and float archives drawn by both GL renderers through a display window: each pixel is
// the window formula of its texel, and NaN samples are transparent.
#include <cmath>
#include <memory>

#include <gtest/gtest.h>

#include <tessera/display_window.h>
#include <tessera/gl.h>
#include <tessera/renderer.h>
#include <tessera/stream.h>

#include "gl_test_context.h"
#include "support/synthetic_archive.h"
#include "support/test_images.h"
#include "support/wide_archive.h"

namespace tessera {
namespace {

constexpr uint32_t kWidth = 150, kHeight = 100;

bool isNoData(uint32_t x, uint32_t y) {
  return x >= 20 && x < 30 && y >= 20 && y < 30;
}

// Sample c of texel (x, y): u16 spread over the whole range, f32 with negatives, fractions
// and a square of NaN.
double sampleOf(SampleType type, uint32_t x, uint32_t y, uint32_t c) {
  if (type == SampleType::kU16) return double((x * 433 + y * 211 + c * 9000) % 65536);
  if (isNoData(x, y)) return NAN;
  return (double(x) - 40) * 0.37 + double(y) * 0.11 - double(c);
}

std::shared_ptr<Archive> buildWide(SampleType type, uint32_t channels) {
  return test::buildWideArchive(
      test::testTempDir() + "wide-" + sampleTypeName(type) + "-" + std::to_string(channels) +
          ".tess",
      kWidth, kHeight, channels, type,
      [type](uint32_t x, uint32_t y, uint32_t c) { return sampleOf(type, x, y, c); });
}

struct Case {
  RendererKind kind;
  SampleType type;
  uint32_t channels;
  DisplayWindow window;
};

class WindowedRenderers : public testing::TestWithParam<Case> {};

TEST_P(WindowedRenderers, EachPixelIsTheWindowFormulaOfItsTexelAndNanIsTransparent) {
  const Case& c = GetParam();
  test::sharedGlContext();
  std::shared_ptr<Archive> archive = buildWide(c.type, c.channels);
  ASSERT_TRUE(archive);
  StreamerOptions streamer_options;
  streamer_options.loader_threads = 1;
  auto streamer = TileStreamer::create(archive, streamer_options);
  ASSERT_TRUE(streamer) << streamer.error().message;
  auto renderer = createRenderer(c.kind, archive->images()[0]);
  ASSERT_TRUE(renderer) << renderer.error().message;
  (*renderer)->setDisplayWindow(c.window);

  // One texel per pixel, pixel centres on texel centres, the whole image on screen.
  View view;
  view.ortho.centre_x = kWidth / 2.0;
  view.ortho.centre_y = kHeight / 2.0;
  view.ortho.texels_per_pixel = 1;
  view.ortho.viewport_w = kWidth;
  view.ortho.viewport_h = kHeight;
  for (int quiet = 0, i = 0; quiet < 2 && i < 500; ++i) {
    const FrameUpdate& update = (*streamer)->update(view);
    (*streamer)->acknowledge((*renderer)->apply(update));
    (*renderer)->draw(view);
    const bool idle = update.uploads.size() == (*renderer)->stats().declined &&
                      update.report.queue_length == 0 && update.report.in_flight == 0;
    quiet = idle ? quiet + 1 : 0;
    (*streamer)->waitIdleForTesting();
  }
  const Picture picture = (*renderer)->readPixels();
  ASSERT_EQ(picture.rgba.size(), size_t(kWidth) * kHeight * 4);

  uint32_t worst = 0, nan_shown = 0, checked = 0;
  for (uint32_t y = 0; y < kHeight; ++y)
    for (uint32_t x = 0; x < kWidth; ++x) {
      const uint8_t* got = &picture.rgba[(size_t(y) * kWidth + x) * 4];
      if (c.type == SampleType::kF32 && isNoData(x, y)) {
        nan_shown += (got[0] | got[1] | got[2] | got[3]) != 0;
        continue;
      }
      // The bilinear footprint of a pixel next to the no-data square holds a NaN texel
      // (docs/rendering.md, "Display window"): not checked.
      if (c.type == SampleType::kF32 && x >= 19 && x <= 30 && y >= 19 && y <= 30) continue;
      for (uint32_t k = 0; k < 3; ++k) {
        const uint8_t want =
            windowSample(sampleOf(c.type, x, y, c.channels == 1 ? 0 : k), c.window);
        worst = std::max<uint32_t>(worst, uint32_t(std::abs(int(got[k]) - int(want))));
      }
      worst = std::max<uint32_t>(worst, uint32_t(255 - got[3]));
      ++checked;
    }
  EXPECT_GT(checked, kWidth * kHeight / 2);
  EXPECT_LE(worst, 1u) << "largest difference from the window formula";
  EXPECT_EQ(nan_shown, 0u) << "NaN texels drawn with a colour";
}

INSTANTIATE_TEST_SUITE_P(
    All, WindowedRenderers,
    testing::Values(Case{RendererKind::kTileQuads, SampleType::kU16, 1, {10000, 50000, 1}},
                    Case{RendererKind::kClipmap, SampleType::kU16, 3, {0, 40000, 0.5}},
                    Case{RendererKind::kTileQuads, SampleType::kF32, 1, {-5, 20, 2}},
                    Case{RendererKind::kClipmap, SampleType::kF32, 1, {-10, 30, 1}}),
    [](const testing::TestParamInfo<Case>& param_info) {
      const Case& c = param_info.param;
      return std::string(c.kind == RendererKind::kClipmap ? "Clipmap_" : "TileQuads_") +
             sampleTypeName(c.type) + "_" + std::to_string(c.channels) + "ch";
    });

}  // namespace
}  // namespace tessera
