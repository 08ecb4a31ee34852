// renderReference: the sampling rules applied to small real archives, checked against an
// independent in-memory pyramid (tests/support/reference_pyramid.h) sampled by hand.
#include <tessera/render.h>

#include <cmath>
#include <set>
#include <tuple>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <tessera/build.h>

#include "support/archive_fixture.h"
#include "support/fault_source.h"
#include "support/reference_pyramid.h"
#include "support/synthetic_archive.h"
#include "support/test_images.h"

namespace tessera {
namespace {

constexpr uint32_t kTile = 64;

struct Rgba {
  double c[4] = {0, 0, 0, 0};
};

/// Texel (x, y) of a level, expanded to RGBA as the rules say.
Rgba texelRgba(const Image& level, uint32_t x, uint32_t y) {
  const uint8_t* t = level.row(y) + size_t(x) * level.channels;
  Rgba out;
  switch (level.channels) {
    case 1: out = {{double(t[0]), double(t[0]), double(t[0]), 255}}; break;
    case 2: out = {{double(t[0]), double(t[0]), double(t[0]), double(t[1])}}; break;
    case 3: out = {{double(t[0]), double(t[1]), double(t[2]), 255}}; break;
    default: out = {{double(t[0]), double(t[1]), double(t[2]), double(t[3])}}; break;
  }
  return out;
}

/// Bilinear at level-0 point (u, v) of a level `level_index` of the pyramid, written from the
/// rule: the four texels around (u, v) / 2^level - 0.5, indices clamped to the level.
Rgba bilinearAt(const Image& level, uint32_t level_index, double u, double v) {
  const double scale = std::ldexp(1.0, -int(level_index));
  const double x = u * scale - 0.5, y = v * scale - 0.5;
  const double fx = x - std::floor(x), fy = y - std::floor(y);
  const int64_t x0 = int64_t(std::floor(x)), y0 = int64_t(std::floor(y));
  auto cx = [&](int64_t i) { return uint32_t(std::clamp<int64_t>(i, 0, level.width_px - 1)); };
  auto cy = [&](int64_t i) { return uint32_t(std::clamp<int64_t>(i, 0, level.height_px - 1)); };
  const Rgba a = texelRgba(level, cx(x0), cy(y0)), b = texelRgba(level, cx(x0 + 1), cy(y0));
  const Rgba c = texelRgba(level, cx(x0), cy(y0 + 1)), d = texelRgba(level, cx(x0 + 1), cy(y0 + 1));
  Rgba out;
  for (int k = 0; k < 4; ++k)
    out.c[k] = (1 - fx) * (1 - fy) * a.c[k] + fx * (1 - fy) * b.c[k] + (1 - fx) * fy * c.c[k] +
               fx * fy * d.c[k];
  return out;
}

uint8_t rounded(double x) {
  return uint8_t(std::clamp(std::floor(x + 0.5), 0.0, 255.0));
}

/// A picture whose in-image pixels are `colour(u, v)`, the rest transparent.
template <typename Colour>
Picture expectedPicture(const View& view, const ImageInfo& info, Colour colour) {
  Picture picture;
  picture.width = view.viewportWidth();
  picture.height = view.viewportHeight();
  picture.rgba.assign(size_t(picture.width) * picture.height * 4, 0);
  for (uint32_t py = 0; py < picture.height; ++py) {
    for (uint32_t px = 0; px < picture.width; ++px) {
      double u = 0, v = 0;
      if (!textureAt(view, px + 0.5, py + 0.5, u, v)) continue;
      if (u < 0 || v < 0 || u >= info.width_px || v >= info.height_px) continue;
      const Rgba c = colour(u, v);
      uint8_t* out = picture.rgba.data() + (size_t(py) * picture.width + px) * 4;
      for (int k = 0; k < 4; ++k) out[k] = rounded(c.c[k]);
    }
  }
  return picture;
}

View orthoView(double cx, double cy, double tpp, uint32_t w, uint32_t h, double rotation = 0) {
  View view;
  view.ortho = {cx, cy, tpp, w, h, rotation};
  return view;
}

/// The view that shows level-0 texel (px, py) at pixel (px, py), centred on texel centres.
View identityView(const ImageInfo& info) {
  return orthoView(info.width_px / 2.0, info.height_px / 2.0, 1, info.width_px, info.height_px);
}

std::string describe(const PictureDifference& d) {
  return fmt::format("psnr {:.2f} dB, max {}, mean {:.4f}", d.psnr_db, d.max_abs, d.mean_abs);
}

/// A lossless archive of a pattern image, its pyramid and the opened archive over memory.
struct Fixture {
  Image image;
  std::unique_ptr<test::ReferencePyramid> pyramid;
  test::BuiltArchive built;
  std::shared_ptr<Archive> archive;

  Fixture(uint32_t w, uint32_t h, uint32_t channels, uint32_t border, Codec codec,
          uint32_t seed = 7) {
    image = test::makePatternImage(w, h, channels, seed);
    pyramid = std::make_unique<test::ReferencePyramid>(image);
    BuildOptions options;
    options.tile_size_px = kTile;
    options.border_px = border;
    options.codec = codec;
    options.threads = 2;
    built = test::buildFromImage(image, options, test::testTempDir());
    if (!built.bytes.empty())
      archive = test::openArchiveOrFail(makeMemorySource(built.bytes, "render.tess"));
  }
  const ImageInfo& info() const { return archive->images()[0]; }
  const Image& level(uint32_t l) const { return pyramid->level(l); }
};

PictureDifference differenceOf(const Picture& a, const Picture& b) {
  Result<PictureDifference> d = comparePictures(a, b);
  EXPECT_TRUE(d) << d.error().message;
  return d ? *d : PictureDifference{};
}

// --- one texel per pixel -------------------------------------------------------------------

class RenderReferenceIdentity : public ::testing::TestWithParam<std::tuple<uint32_t, uint32_t>> {};

TEST_P(RenderReferenceIdentity, ReproducesLevelZeroTexelsExactly) {
  const auto [channels, border] = GetParam();
  Fixture f(131, 77, channels, border, Codec::kZstd);
  ASSERT_TRUE(f.archive);
  ASSERT_GE(f.info().level_count, 2u);
  const View view = identityView(f.info());
  Result<Picture> picture = renderReference(*f.archive, view);
  ASSERT_TRUE(picture) << picture.error().message;
  ASSERT_EQ(picture->width, 131u);
  ASSERT_EQ(picture->height, 77u);
  for (uint32_t y = 0; y < 77; ++y) {
    for (uint32_t x = 0; x < 131; ++x) {
      const Rgba want = texelRgba(f.level(0), x, y);
      const uint8_t* got = picture->rgba.data() + (size_t(y) * 131 + x) * 4;
      for (int k = 0; k < 4; ++k)
        ASSERT_EQ(got[k], want.c[k]) << "pixel " << x << "," << y << " channel " << k;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(ChannelsAndBorders, RenderReferenceIdentity,
                         ::testing::Combine(::testing::Values(1u, 2u, 3u, 4u),
                                            ::testing::Values(0u, 3u)));

// --- 2^k texels per pixel ------------------------------------------------------------------

class RenderReferenceZoom : public ::testing::TestWithParam<Codec> {};

TEST_P(RenderReferenceZoom, PowerOfTwoZoomIsBilinearOfThatLevel) {
  Fixture f(300, 200, 3, 1, GetParam());
  ASSERT_TRUE(f.archive);
  ASSERT_EQ(f.info().level_count, 4u);  // 300x200, 150x100, 75x50, 38x25
  for (uint32_t k : {1u, 2u, 3u}) {
    // Off texel centres, rotated, and reaching past the image's edges.
    for (double rotation : {0.0, 0.4}) {
      const View view = orthoView(151.3, 97.8, std::ldexp(1.0, int(k)), 90, 70, rotation);
      Result<Picture> picture = renderReference(*f.archive, view);
      ASSERT_TRUE(picture) << picture.error().message;
      const Picture want = expectedPicture(
          view, f.info(), [&](double u, double v) { return bilinearAt(f.level(k), k, u, v); });
      const PictureDifference d = differenceOf(*picture, want);
      EXPECT_EQ(d.max_abs, 0u) << "level " << k << " rotation " << rotation << ": " << describe(d);
    }
  }
}

INSTANTIATE_TEST_SUITE_P(LosslessCodecs, RenderReferenceZoom,
                         ::testing::Values(Codec::kRaw, Codec::kPng, Codec::kZstd),
                         [](const auto& param_info) {
                           return std::string(codecName(param_info.param));
                         });

TEST(RenderReference, CoarserThanTheCoarsestLevelMinifiesIt) {
  Fixture f(300, 200, 4, 0, Codec::kZstd);
  ASSERT_TRUE(f.archive);
  const uint32_t coarsest = f.info().level_count - 1;
  const View view = orthoView(150, 100, 37, 12, 9);  // lambda 5.2, past level 3
  Result<Picture> picture = renderReference(*f.archive, view);
  ASSERT_TRUE(picture) << picture.error().message;
  const Picture want = expectedPicture(view, f.info(), [&](double u, double v) {
    return bilinearAt(f.level(coarsest), coarsest, u, v);
  });
  EXPECT_EQ(differenceOf(*picture, want).max_abs, 0u);
}

TEST(RenderReference, MagnificationSamplesLevelZeroBilinearly) {
  Fixture f(150, 100, 3, 2, Codec::kRaw);
  ASSERT_TRUE(f.archive);
  const View view = orthoView(60.2, 41.7, 0.3, 40, 30, 0.2);  // lambda < 0
  Result<Picture> picture = renderReference(*f.archive, view);
  ASSERT_TRUE(picture) << picture.error().message;
  const Picture want = expectedPicture(
      view, f.info(), [&](double u, double v) { return bilinearAt(f.level(0), 0, u, v); });
  EXPECT_EQ(differenceOf(*picture, want).max_abs, 0u);
}

// --- trilinear --------------------------------------------------------------------------

TEST(RenderReference, HalfwayBetweenLevelsIsTheirAverage) {
  Fixture f(300, 200, 4, 1, Codec::kZstd);
  ASSERT_TRUE(f.archive);
  const View view = orthoView(140.6, 90.1, std::exp2(1.5), 60, 40);  // lambda 1.5
  Result<Picture> picture = renderReference(*f.archive, view);
  ASSERT_TRUE(picture) << picture.error().message;
  const Picture average = expectedPicture(view, f.info(), [&](double u, double v) {
    const Rgba a = bilinearAt(f.level(1), 1, u, v), b = bilinearAt(f.level(2), 2, u, v);
    Rgba out;
    for (int k = 0; k < 4; ++k) out.c[k] = 0.5 * a.c[k] + 0.5 * b.c[k];
    return out;
  });
  const Picture level1 = expectedPicture(
      view, f.info(), [&](double u, double v) { return bilinearAt(f.level(1), 1, u, v); });
  const PictureDifference to_average = differenceOf(*picture, average);
  // lambda - L is 0.5 up to the last bit of log2: a sum that ends in exactly .5 may round
  // either way.
  EXPECT_LE(to_average.max_abs, 1u) << describe(to_average);
  EXPECT_LT(to_average.mean_abs, 0.01) << describe(to_average);
  const PictureDifference to_level1 = differenceOf(*picture, level1);
  EXPECT_GT(to_level1.max_abs, 10u) << "no blend with level 2: " << describe(to_level1);
}

// --- the fallback -----------------------------------------------------------------------

TEST(RenderReference, WithoutLevelZeroTilesShowsLevelOneMagnified) {
  Fixture f(131, 77, 3, 0, Codec::kZstd);
  ASSERT_TRUE(f.archive);
  const View view = identityView(f.info());
  ReferenceOptions options;
  options.available = [](const TileId& id) { return id.level != 0; };
  Result<Picture> picture = renderReference(*f.archive, view, options);
  ASSERT_TRUE(picture) << picture.error().message;
  const Picture want = expectedPicture(
      view, f.info(), [&](double u, double v) { return bilinearAt(f.level(1), 1, u, v); });
  const PictureDifference d = differenceOf(*picture, want);
  EXPECT_EQ(d.max_abs, 0u) << describe(d);
}

TEST(RenderReference, OneMissingTileFallsBackOnlyWhereItLies) {
  Fixture f(131, 77, 3, 0, Codec::kZstd);
  ASSERT_TRUE(f.archive);
  const View view = identityView(f.info());
  ReferenceOptions options;
  options.available = [](const TileId& id) { return !(id.level == 0 && id.x == 1 && id.y == 0); };
  Result<Picture> picture = renderReference(*f.archive, view, options);
  ASSERT_TRUE(picture) << picture.error().message;
  const Picture want = expectedPicture(view, f.info(), [&](double u, double v) {
    const bool missing = u >= kTile && u < 2 * kTile && v < kTile;
    return missing ? bilinearAt(f.level(1), 1, u, v)
                   : texelRgba(f.level(0), uint32_t(u), uint32_t(v));
  });
  const PictureDifference d = differenceOf(*picture, want);
  EXPECT_EQ(d.max_abs, 0u) << describe(d);
  // And the missing tile's area does differ from level 0.
  const Picture level0 = expectedPicture(view, f.info(), [&](double u, double v) {
    return texelRgba(f.level(0), uint32_t(u), uint32_t(v));
  });
  EXPECT_GT(differenceOf(*picture, level0).max_abs, 10u);
}

TEST(RenderReference, LevelsShownNameTheLevelEachPixelDrawsFrom) {
  Fixture f(131, 77, 3, 0, Codec::kZstd);
  ASSERT_TRUE(f.archive);
  // The image's top-left corner mid-screen at 1 texel per pixel, level-0 tile (1, 0) missing.
  const View view = orthoView(80, 0, 1, 40, 10);
  ReferenceOptions options;
  options.available = [](const TileId& id) { return !(id.level == 0 && id.x == 1 && id.y == 0); };
  Result<std::vector<int32_t>> levels = levelsShown(*f.archive, view, options);
  ASSERT_TRUE(levels) << levels.error().message;
  ASSERT_EQ(levels->size(), 400u);
  for (uint32_t y = 0; y < 10; ++y)
    for (uint32_t x = 0; x < 40; ++x) {
      const double u = 60.5 + x, v = double(y) - 4.5;
      const int32_t want = v < 0 ? -1 : (u >= kTile && u < 2 * kTile ? 1 : 0);
      EXPECT_EQ((*levels)[size_t(y) * 40 + x], want) << x << "," << y;
    }
  // Zoomed out to 3 texels per pixel: level 1 wherever the image is.
  Result<std::vector<int32_t>> zoomed = levelsShown(*f.archive, orthoView(65, 38, 3, 20, 10));
  ASSERT_TRUE(zoomed);
  EXPECT_EQ(std::count(zoomed->begin(), zoomed->end(), 1), 200);
}

TEST(RenderReference, NothingAvailableIsTransparent) {
  Fixture f(131, 77, 3, 0, Codec::kZstd);
  ASSERT_TRUE(f.archive);
  ReferenceOptions options;
  uint32_t asked = 0;
  options.available = [&](const TileId&) {
    ++asked;
    return false;
  };
  Result<Picture> picture = renderReference(*f.archive, identityView(f.info()), options);
  ASSERT_TRUE(picture) << picture.error().message;
  EXPECT_EQ(std::count(picture->rgba.begin(), picture->rgba.end(), 0), picture->rgba.size());
  // Each tile is asked about once: 3x2 + 2x1 + 1 tiles.
  EXPECT_EQ(asked, 9u);
}

// --- outside the image and perspective ---------------------------------------------------

TEST(RenderReference, PixelsOutsideTheImageAreTransparent) {
  Fixture f(131, 77, 3, 0, Codec::kZstd);
  ASSERT_TRUE(f.archive);
  const View view = orthoView(0, 0, 1, 20, 10);  // the image's top-left corner mid-screen
  Result<Picture> picture = renderReference(*f.archive, view);
  ASSERT_TRUE(picture) << picture.error().message;
  for (uint32_t y = 0; y < 10; ++y) {
    for (uint32_t x = 0; x < 20; ++x) {
      const uint8_t* p = picture->rgba.data() + (size_t(y) * 20 + x) * 4;
      const bool inside = x >= 10 && y >= 5;
      if (inside) {
        const Rgba want = texelRgba(f.level(0), x - 10, y - 5);
        EXPECT_EQ(p[0], want.c[0]) << x << "," << y;
        EXPECT_EQ(p[3], 255) << x << "," << y;
      } else {
        EXPECT_EQ(p[0] | p[1] | p[2] | p[3], 0) << x << "," << y;
      }
    }
  }
}

TEST(RenderReference, PerspectiveShowsTheGroundBelowTheHorizonOnly) {
  Fixture f(300, 200, 3, 1, Codec::kZstd);
  ASSERT_TRUE(f.archive);
  View view;
  view.kind = View::Kind::kPerspective;
  view.perspective = {150, 300, 40, 0, -0.3, 1.0, 64, 48};  // south of the image, looking north
  Result<Picture> picture = renderReference(*f.archive, view);
  ASSERT_TRUE(picture) << picture.error().message;
  uint32_t opaque = 0;
  for (uint32_t y = 0; y < 48; ++y) {
    for (uint32_t x = 0; x < 64; ++x) {
      const uint8_t alpha = picture->rgba[(size_t(y) * 64 + x) * 4 + 3];
      double u = 0, v = 0;
      const bool hit = textureAt(view, x + 0.5, y + 0.5, u, v);
      const bool inside = hit && u >= 0 && v >= 0 && u < 300 && v < 200;
      EXPECT_EQ(alpha, inside ? 255 : 0) << x << "," << y;
      opaque += alpha == 255;
    }
  }
  EXPECT_GT(opaque, 200u);
  EXPECT_EQ(picture->rgba[3], 0);  // the top-left pixel is sky
}

TEST(RenderReference, PerspectiveStraightDownEqualsTheOrthographicPicture) {
  Fixture f(300, 200, 4, 1, Codec::kZstd);
  ASSERT_TRUE(f.archive);
  View persp;
  persp.kind = View::Kind::kPerspective;
  persp.perspective = {150, 100, 300, 0, -1.5707963267948966, 0.8, 48, 40};
  const double tpp = 300 * 2 * std::tan(0.4) / 40;  // eye_z * pixelAngle, lambda 2.69
  Result<Picture> a = renderReference(*f.archive, persp);
  Result<Picture> b = renderReference(*f.archive, orthoView(150, 100, tpp, 48, 40));
  ASSERT_TRUE(a && b);
  const PictureDifference d = differenceOf(*a, *b);
  EXPECT_LE(d.max_abs, 1u) << describe(d);
  EXPECT_GT(d.psnr_db, 60) << describe(d);
}

// --- failures and reads -------------------------------------------------------------------

TEST(RenderReference, CorruptTileFailsNamingTheTile) {
  Fixture f(300, 200, 3, 0, Codec::kZstd);
  ASSERT_TRUE(f.archive);
  const TileId victim{0, 0, 2, 1};
  Result<TileEntry> entry = f.archive->tileEntry(victim);
  ASSERT_TRUE(entry) << entry.error().message;
  ASSERT_EQ(entry->kind, TileKind::kEncoded);
  std::vector<uint8_t> bytes = f.built.bytes;
  test::flipBit(bytes, entry->offset_bytes + entry->length_bytes / 2, 3);
  auto corrupt = test::openArchiveOrFail(makeMemorySource(bytes, "corrupt.tess"));
  ASSERT_TRUE(corrupt);
  Result<Picture> picture = renderReference(*corrupt, identityView(f.info()));
  ASSERT_FALSE(picture);
  EXPECT_EQ(picture.error().code, ErrorCode::kCorrupt);
  EXPECT_NE(picture.error().message.find("corrupt.tess"), std::string::npos)
      << picture.error().message;
  EXPECT_NE(picture.error().message.find("tile (0,2,1)"), std::string::npos)
      << picture.error().message;
  // A view that does not reach the tile is fine.
  EXPECT_TRUE(renderReference(*corrupt, orthoView(32, 32, 1, 40, 40)));
}

TEST(RenderReference, UnreadableTileFailsNamingTheTile) {
  Fixture f(131, 77, 3, 0, Codec::kZstd);
  ASSERT_TRUE(f.archive);
  auto faulty = std::make_shared<test::FaultSource>(makeMemorySource(f.built.bytes, "flaky.tess"));
  auto archive = test::openArchiveOrFail(faulty);
  ASSERT_TRUE(archive);
  test::warmDirectory(*archive);
  faulty->setFaults({test::FaultKind::kError});
  Result<Picture> picture = renderReference(*archive, identityView(f.info()));
  ASSERT_FALSE(picture);
  EXPECT_EQ(picture.error().code, ErrorCode::kIo);
  EXPECT_NE(picture.error().message.find("flaky.tess: tile (0,"), std::string::npos)
      << picture.error().message;
}

TEST(RenderReference, ReadsEachTileOncePerCall) {
  Fixture f(300, 200, 3, 2, Codec::kZstd);
  ASSERT_TRUE(f.archive);
  auto counting = std::make_shared<test::FaultSource>(makeMemorySource(f.built.bytes, "c.tess"));
  auto archive = test::openArchiveOrFail(counting);
  ASSERT_TRUE(archive);
  test::warmDirectory(*archive);
  // Level 0 at one texel per pixel: every level-0 tile, and only those.
  uint32_t encoded = 0;
  for (uint32_t y = 0; y < f.info().tilesY(0); ++y)
    for (uint32_t x = 0; x < f.info().tilesX(0); ++x)
      encoded += (*archive->tileEntry({0, 0, x, y})).kind == TileKind::kEncoded;
  ASSERT_GT(encoded, 2u);
  const uint64_t before = counting->reads();
  ASSERT_TRUE(renderReference(*archive, identityView(f.info())));
  EXPECT_EQ(counting->reads() - before, encoded);
}

TEST(RenderReference, UnknownImageIsInvalidArgument) {
  Fixture f(131, 77, 3, 0, Codec::kZstd);
  ASSERT_TRUE(f.archive);
  View view = identityView(f.info());
  view.image = 3;
  Result<Picture> picture = renderReference(*f.archive, view);
  ASSERT_FALSE(picture);
  EXPECT_EQ(picture.error().code, ErrorCode::kInvalidArgument);
}

}  // namespace
}  // namespace tessera
