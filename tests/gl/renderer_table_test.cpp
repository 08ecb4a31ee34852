// The backend table: one row per RendererKind, names that round-trip, and the checks
// createRenderer makes before a backend runs (no GL context needed for these).
#include <tessera/renderer.h>

#include <gtest/gtest.h>

namespace tessera {
namespace {

ImageInfo rgbImage() {
  ImageInfo info;
  info.width_px = info.height_px = 512;
  info.channels = 3;
  info.tile_size_px = 64;
  info.level_count = levelCountFor(512, 512, 64);
  return info;
}

TEST(RendererTable, EveryKindHasANameThatLeadsBackToIt) {
  for (int k = 0; k < int(RendererKind::kCount); ++k) {
    const RendererKind kind = RendererKind(k);
    const std::optional<RendererKind> named = rendererNamed(rendererName(kind));
    ASSERT_TRUE(named) << rendererName(kind);
    EXPECT_EQ(*named, kind);
  }
  EXPECT_STREQ(rendererName(RendererKind::kTileQuads), "tile-quads");
  EXPECT_STREQ(rendererName(RendererKind::kClipmap), "clipmap");
}

TEST(RendererTable, UnknownNamesAndKindsAreRejected) {
  EXPECT_FALSE(rendererNamed("vulkan"));
  EXPECT_FALSE(rendererNamed(""));
  EXPECT_STREQ(rendererName(RendererKind::kCount), "unknown");
  auto made = createRenderer(RendererKind::kCount, rgbImage());
  ASSERT_FALSE(made);
  EXPECT_EQ(made.error().code, ErrorCode::kInvalidArgument);
}

TEST(RendererTable, AnImageNoRendererCanHoldIsRejectedNamingTheRenderer) {
  ImageInfo info = rgbImage();
  info.channels = 5;
  auto made = createRenderer(RendererKind::kClipmap, info);
  ASSERT_FALSE(made);
  EXPECT_EQ(made.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(made.error().message.find("clipmap"), std::string::npos) << made.error().message;
}

}  // namespace
}  // namespace tessera
