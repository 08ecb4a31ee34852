// The compositor: blend modes and filtering against texels computed by hand, the fast path
// against the brute-force reference at every level, errors for missing brushes, and a pinned
// hash (deterministic to the bit).
#include <tessera/procedural.h>

#include <algorithm>

#include <gtest/gtest.h>
#include <xxhash.h>

#include "procedural/kernel.h"
#include "procedural/procedural_fixtures.h"

namespace tessera {
namespace {

using testing::randomInstances;
using testing::solidImage;
using testing::testBrushes;

std::shared_ptr<const BrushSet> prepare(std::vector<Brush> brushes, uint32_t w, uint32_t h,
                                        Image layer = {}) {
  auto set = BrushSet::prepare(std::move(brushes), UnderlyingLayer{std::move(layer)}, w, h);
  EXPECT_TRUE(set) << set.error().message;
  return *set;
}

Brush brushOf(Image image, BlendMode mode = BlendMode::kNormal) {
  Brush brush;
  brush.name = "b";
  brush.blend = mode;
  brush.images.push_back(std::move(image));
  return brush;
}

TileGeometry tileAt(uint32_t level, uint32_t x, uint32_t y, uint32_t w, uint32_t h,
                    uint32_t tile = 64, uint32_t border = 0) {
  return {level, x, y, tile, border, w, h};
}

const uint8_t* texel(const Image& image, uint32_t i, uint32_t j) {
  return &image.texels[(size_t(j) * image.width_px + i) * 4];
}

TEST(Div255, IsRoundedDivisionOverItsWholeRange) {
  for (uint32_t x = 0; x <= 255 * 255; ++x) ASSERT_EQ(detail::div255(x), (x + 127) / 255) << x;
}

TEST(Compositor, OneBrushTexelPerLevelTexelCopiesTheImage) {
  Image image(4, 4, 4);
  for (size_t i = 0; i < image.texels.size(); ++i) image.texels[i] = uint8_t(i * 7 + 1);
  for (size_t i = 3; i < image.texels.size(); i += 4) image.texels[i] = 255;
  auto set = prepare({brushOf(image)}, 64, 64);
  BrushInstance instance;
  instance.x_px = 10;
  instance.y_px = 10;
  instance.radius_px = 2;  // 4 brush texels over 4 level-0 texels
  Image out;
  ASSERT_TRUE(compositeTile(*set, tileAt(0, 0, 0, 64, 64), {&instance, 1}, out));
  for (uint32_t j = 0; j < 4; ++j)
    for (uint32_t i = 0; i < 4; ++i)
      for (int c = 0; c < 4; ++c)
        EXPECT_EQ(texel(out, 8 + i, 8 + j)[c], image.texels[(j * 4 + i) * 4 + c]) << i << j << c;
  EXPECT_EQ(texel(out, 7, 9)[3], 0);  // the tap left of the image is transparent
  EXPECT_EQ(texel(out, 12, 9)[3], 0);
}

TEST(Compositor, HalfTexelOffsetBlendsWithTransparentBorderNotBlack) {
  auto set = prepare({brushOf(solidImage(4, 4, 200, 100, 50, 255))}, 64, 64);
  BrushInstance instance;
  instance.x_px = 10.5;
  instance.y_px = 10;
  instance.radius_px = 2;
  Image out;
  ASSERT_TRUE(compositeTile(*set, tileAt(0, 0, 0, 64, 64), {&instance, 1}, out));
  // Texel 8's centre is half a brush texel left of the image: half alpha, the edge's colour.
  const uint8_t expected[4] = {200, 100, 50, 128};
  EXPECT_TRUE(std::equal(expected, expected + 4, texel(out, 8, 9)));
  EXPECT_EQ(texel(out, 9, 9)[3], 255);
  EXPECT_EQ(texel(out, 12, 9)[3], 128);
}

// Backdrop (100, 150, 200) opaque; source (200, 100, 50) at alpha 128; the values below are
// the formulas of docs/procedural.md worked by hand.
TEST(Compositor, BlendModesMatchHandComputedTexels) {
  struct Case {
    BlendMode mode;
    uint8_t expected[3];
  };
  const Case cases[] = {{BlendMode::kNormal, {150, 125, 125}},
                        {BlendMode::kMultiply, {89, 104, 119}},
                        {BlendMode::kAdd, {178, 200, 225}},
                        {BlendMode::kOverlay, {129, 138, 183}}};
  for (const Case& c : cases) {
    auto set = prepare({brushOf(solidImage(16, 16, 100, 150, 200, 255)),
                        brushOf(solidImage(16, 16, 200, 100, 50, 255), c.mode)},
                       64, 64);
    BrushInstance base, top;
    base.x_px = base.y_px = 32;
    base.radius_px = 40;
    top = base;
    top.brush = 1;
    top.radius_px = 20;
    top.opacity = 128;
    top.id = 1;
    BrushInstance instances[] = {base, top};
    Image out;
    ASSERT_TRUE(compositeTile(*set, tileAt(0, 0, 0, 64, 64), instances, out));
    const uint8_t* t = texel(out, 32, 32);
    EXPECT_EQ(t[0], c.expected[0]) << blendModeName(c.mode);
    EXPECT_EQ(t[1], c.expected[1]) << blendModeName(c.mode);
    EXPECT_EQ(t[2], c.expected[2]) << blendModeName(c.mode);
    EXPECT_EQ(t[3], 255);
  }
}

TEST(Compositor, TransparentBackdropTakesTheSourceAsItIs) {
  auto set =
      prepare({brushOf(solidImage(16, 16, 200, 100, 50, 255), BlendMode::kMultiply)}, 64, 64);
  BrushInstance instance;
  instance.x_px = instance.y_px = 32;
  instance.radius_px = 20;
  instance.opacity = 100;
  Image out;
  ASSERT_TRUE(compositeTile(*set, tileAt(0, 0, 0, 64, 64), {&instance, 1}, out));
  const uint8_t expected[4] = {200, 100, 50, 100};
  EXPECT_TRUE(std::equal(expected, expected + 4, texel(out, 32, 32)));
}

TEST(Compositor, TintMultipliesColourAndAlpha) {
  auto set = prepare({brushOf(solidImage(16, 16, 200, 100, 50, 255))}, 64, 64);
  BrushInstance instance;
  instance.x_px = instance.y_px = 32;
  instance.radius_px = 20;
  instance.tint_rgba = 0xFF00FF80u;  // r 0x80, g 0xFF, b 0, a 0xFF
  Image out;
  ASSERT_TRUE(compositeTile(*set, tileAt(0, 0, 0, 64, 64), {&instance, 1}, out));
  const uint8_t expected[4] = {100, 100, 0, 255};  // 200 * 128 / 255 = 100.4
  EXPECT_TRUE(std::equal(expected, expected + 4, texel(out, 32, 32)));
}

// A checkerboard of single texels seen at level 1 (two brush texels per level texel) samples
// mip 1, whose texels are the alpha-weighted means, 128 gray: not the aliased black or white
// that point-sampling level 0 would give.
TEST(Compositor, CoarserLevelsSampleTheBrushMipPyramid) {
  Image checker(8, 8, 4);
  for (uint32_t y = 0; y < 8; ++y)
    for (uint32_t x = 0; x < 8; ++x) {
      uint8_t v = (x + y) % 2 ? 255 : 0;
      uint8_t* t = &checker.texels[(y * 8 + x) * 4];
      t[0] = t[1] = t[2] = v;
      t[3] = 255;
    }
  auto set = prepare({brushOf(checker)}, 64, 64);
  BrushInstance instance;
  instance.x_px = instance.y_px = 16;
  instance.radius_px = 4;
  Image out;
  ASSERT_TRUE(compositeTile(*set, tileAt(1, 0, 0, 64, 64), {&instance, 1}, out));
  for (uint32_t i = 6; i < 10; ++i) {
    EXPECT_EQ(texel(out, i, 7)[0], 128) << i;
    EXPECT_EQ(texel(out, i, 7)[3], 255) << i;
  }
  ASSERT_TRUE(compositeTile(*set, tileAt(0, 0, 0, 64, 64), {&instance, 1}, out));
  EXPECT_EQ(texel(out, 12, 12)[0], 0);
  EXPECT_EQ(texel(out, 13, 12)[0], 255);
}

TEST(Compositor, RotationTurnsTheImage) {
  Image halves(16, 16, 4);
  for (uint32_t y = 0; y < 16; ++y)
    for (uint32_t x = 0; x < 16; ++x) {
      uint8_t* t = &halves.texels[(y * 16 + x) * 4];
      t[0] = y < 8 ? 255 : 0;  // top red, bottom blue
      t[2] = y < 8 ? 0 : 255;
      t[3] = 255;
    }
  auto set = prepare({brushOf(halves)}, 64, 64);
  BrushInstance instance;
  instance.x_px = instance.y_px = 32;
  instance.radius_px = 16;
  instance.rotation_rad = float(3.14159265358979 / 2);
  Image out;
  ASSERT_TRUE(compositeTile(*set, tileAt(0, 0, 0, 64, 64), {&instance, 1}, out));
  // Brush (u, v) = (8 + dy/2, 8 - dx/2): the top half (v < 8) lies right of the centre.
  EXPECT_EQ(texel(out, 40, 32)[0], 255);
  EXPECT_EQ(texel(out, 24, 32)[2], 255);
}

TEST(Compositor, SlopeMaskDrawsOnlyWhereSteep) {
  Image layer(64, 64, 1);
  for (uint32_t y = 0; y < 64; ++y)
    for (uint32_t x = 0; x < 64; ++x)
      layer.texels[y * 64 + x] = x < 32 ? 10 : uint8_t(10 + (x - 32) * 7);
  Brush rock = brushOf(solidImage(16, 16, 120, 110, 100, 255));
  rock.mask = MaskSource::kSlope;
  rock.mask_low = 10;
  rock.mask_high = 20;
  auto set = prepare({rock}, 64, 64, layer);
  BrushInstance instance;
  instance.x_px = instance.y_px = 32;
  instance.radius_px = 40;
  Image out;
  ASSERT_TRUE(compositeTile(*set, tileAt(0, 0, 0, 64, 64), {&instance, 1}, out));
  EXPECT_EQ(texel(out, 10, 10)[3], 0);    // flat: slope 0
  EXPECT_EQ(texel(out, 50, 10)[3], 255);  // slope 2 * 14 = 28 > 20
}

TEST(Compositor, MissingBrushIsAnErrorNotAPicture) {
  auto set = prepare({brushOf(solidImage(4, 4, 1, 2, 3, 255))}, 64, 64);
  BrushInstance instance;
  instance.brush = 5;
  instance.id = 77;
  Image out;
  auto result = compositeTile(*set, tileAt(0, 0, 0, 64, 64), {&instance, 1}, out);
  ASSERT_FALSE(result);
  EXPECT_EQ(result.error().code, ErrorCode::kCorrupt);
  EXPECT_NE(result.error().message.find("brush 5"), std::string::npos);
}

// The fast compositor (spans within each instance's reach, layer values cached per tile) equals
// the brute force (every instance at every texel, layers sampled per texel) to the bit, at every
// level, with borders and an image size that is no multiple of the tile.
TEST(Compositor, EqualsBruteForceReferenceAtEveryLevel) {
  const uint32_t w = 300, h = 200;
  auto set = prepare(testBrushes(), w, h, testing::heightLayer(75, 50));
  std::vector<BrushInstance> instances =
      randomInstances(400, w, h, uint32_t(set->brushes().size()), 42);
  std::sort(instances.begin(), instances.end(), drawsBefore);
  const uint32_t levels = levelCountFor(w, h, 64);
  size_t compared = 0;
  for (uint32_t border : {0u, 3u}) {
    for (uint32_t level = 0; level < levels; ++level) {
      TileGeometry probe = tileAt(level, 0, 0, w, h, 64, border);
      uint32_t tiles_x = (std::max(1u, (w + (1u << level) - 1) >> level) + 63) / 64;
      uint32_t tiles_y = (std::max(1u, (h + (1u << level) - 1) >> level) + 63) / 64;
      for (uint32_t ty = 0; ty < tiles_y; ++ty) {
        for (uint32_t tx = 0; tx < tiles_x; ++tx) {
          probe.x = tx;
          probe.y = ty;
          Image fast, reference;
          ASSERT_TRUE(compositeTile(*set, probe, instances, fast));
          ASSERT_TRUE(compositeTileReference(*set, probe, instances, reference));
          ASSERT_EQ(fast.texels, reference.texels)
              << "level " << level << " tile " << tx << "," << ty << " border " << border;
          ++compared;
        }
      }
    }
  }
  EXPECT_GT(compared, 20u);
}

// Every instance that draws a texel of a tile meets the tile's query box: the spatial query
// never misses an instance. The first case is the one that a mixed archive with a base layer
// found: a large base instance whose magnified brush fringe passes its box's corner at level 1.
TEST(Compositor, QueryBoxContainsEveryInstanceThatDraws) {
  const uint32_t w = 700, h = 500;
  auto set = prepare(testBrushes(), w, h, testing::heightLayer(70, 50));
  std::vector<BrushInstance> instances =
      randomInstances(300, w, h, uint32_t(set->brushes().size()), 29);
  // Instance 241 of the base test's set (seed 29): brush 0, a 16 x 16 opaque square magnified
  // about 31 times, centre (152, 100), radius * scale 250; then the same at other rotations.
  BrushInstance fringe = randomInstances(500, w, h, uint32_t(set->brushes().size()), 29)[240];
  ASSERT_EQ(fringe.brush, 0u);
  ASSERT_NEAR(fringe.x_px, 152.17, 0.01);
  instances.push_back(fringe);
  for (float rotation : {0.f, 0.4f, 0.785f, 1.2f, 2.5f, -0.785f}) {
    fringe.rotation_rad = rotation;
    instances.push_back(fringe);
  }
  const uint32_t levels = levelCountFor(w, h, 128);
  uint64_t checked = 0;
  for (const BrushInstance& instance : instances) {
    for (uint32_t level = 0; level < levels; ++level) {
      const uint32_t tiles_x = (std::max(1u, (w + (1u << level) - 1) >> level) + 127) / 128;
      const uint32_t tiles_y = (std::max(1u, (h + (1u << level) - 1) >> level) + 127) / 128;
      for (uint32_t ty = 0; ty < tiles_y; ++ty)
        for (uint32_t tx = 0; tx < tiles_x; ++tx) {
          const TileGeometry tile = tileAt(level, tx, ty, w, h, 128, 1);
          if (instanceBounds(instance).intersects(tileQueryBox(tile))) continue;
          Image alone;
          ASSERT_TRUE(compositeTileReference(*set, tile, std::span(&instance, 1), alone));
          const bool draws = std::any_of(alone.texels.begin(), alone.texels.end(),
                                         [](uint8_t t) { return t != 0; });
          ASSERT_FALSE(draws) << "instance " << instance.id << " rotation " << instance.rotation_rad
                              << " draws into tile (" << level << "," << tx << "," << ty
                              << ") outside its query box";
          ++checked;
        }
    }
  }
  EXPECT_GT(checked, 1000u);  // (instance, tile) pairs outside the boxes
}

// Pinned from this implementation: any change to the arithmetic, the mip rule or the sine and
// cosine changes this hash, and every machine must produce it.
TEST(Compositor, OutputIsPinnedToTheBit) {
  auto set = prepare(testBrushes(), 256, 256, testing::heightLayer(64, 64));
  std::vector<BrushInstance> instances = randomInstances(200, 256, 256, 7, 7);
  std::sort(instances.begin(), instances.end(), drawsBefore);
  uint64_t hash = 0;
  for (uint32_t level = 0; level < 3; ++level) {
    Image out;
    ASSERT_TRUE(compositeTile(*set, tileAt(level, 0, 0, 256, 256, 128, 2), instances, out));
    hash ^= XXH3_64bits(out.texels.data(), out.texels.size()) + level;
  }
  EXPECT_EQ(hash, 0x7505d5f82565d7dbull) << std::hex << hash;
}

}  // namespace
}  // namespace tessera
