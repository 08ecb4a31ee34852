// ptm coded against its parent: whole pyramids of the integer floor average (Marvie &
// Bouatouch, eq. 3) round-trip bit-exactly tile by tile, coarse to fine, for odd sizes, every
// channel count and odd and even borders; hostile payloads and wrong parents are rejected
// without crashing. Coding without a parent is covered with the other codecs in codec_test.cpp.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <optional>
#include <vector>

#include <gtest/gtest.h>

#include "format/codec.h"
#include "format/codec_internal.h"

namespace tessera::detail {
namespace {

uint32_t nextRandom(uint32_t& state) {
  state ^= state << 13;
  state ^= state >> 17;
  state ^= state << 5;
  return state;
}

// Smooth shading, an edge and noise: residuals that are neither all zero nor all random.
Image makeLevel0(uint32_t width, uint32_t height, uint32_t channels, uint32_t seed) {
  Image image(width, height, channels);
  uint32_t random = seed * 2654435761u + 7;
  for (uint32_t y = 0; y < height; ++y)
    for (uint32_t x = 0; x < width; ++x)
      for (uint32_t c = 0; c < channels; ++c) {
        int value = int(128 + 90 * std::sin(x * 0.05 + c) * std::cos(y * 0.03)) +
                    (x > width / 2 ? 40 : 0) + int(nextRandom(random) % 9) - 4;
        image.row(y)[size_t(x) * channels + c] = uint8_t(std::clamp(value, 0, 255));
      }
  return image;
}

// The pyramid step ptm requires, written independently of src/build: floor of the 2x2 sum
// over the level extended by replicating its last row and column.
Image floorDownsample(const Image& level) {
  Image out((level.width_px + 1) / 2, (level.height_px + 1) / 2, level.channels);
  for (uint32_t y = 0; y < out.height_px; ++y)
    for (uint32_t x = 0; x < out.width_px; ++x)
      for (uint32_t c = 0; c < level.channels; ++c) {
        uint32_t sum = 0;
        for (uint32_t dy = 0; dy < 2; ++dy)
          for (uint32_t dx = 0; dx < 2; ++dx) {
            uint32_t sx = std::min(2 * x + dx, level.width_px - 1);
            uint32_t sy = std::min(2 * y + dy, level.height_px - 1);
            sum += level.row(sy)[size_t(sx) * level.channels + c];
          }
        out.row(y)[size_t(x) * level.channels + c] = uint8_t(sum / 4);
      }
  return out;
}

// docs/format.md, "Tiles": texels clamped into the level.
Image cutStoredTile(const Image& level, uint32_t tile_px, uint32_t border_px, uint32_t x,
                    uint32_t y) {
  const uint32_t side = tile_px + 2 * border_px;
  Image tile(side, side, level.channels);
  for (uint32_t j = 0; j < side; ++j)
    for (uint32_t i = 0; i < side; ++i) {
      int64_t lx = std::clamp<int64_t>(int64_t(x) * tile_px - border_px + i, 0, level.width_px - 1);
      int64_t ly =
          std::clamp<int64_t>(int64_t(y) * tile_px - border_px + j, 0, level.height_px - 1);
      std::memcpy(tile.row(j) + size_t(i) * level.channels,
                  level.row(uint32_t(ly)) + size_t(lx) * level.channels, level.channels);
    }
  return tile;
}

struct PyramidTiles {
  uint32_t tile_px, border_px;
  std::vector<Image> levels;
  uint32_t tilesX(uint32_t l) const { return (levels[l].width_px + tile_px - 1) / tile_px; }
  uint32_t tilesY(uint32_t l) const { return (levels[l].height_px + tile_px - 1) / tile_px; }
  Image tile(uint32_t l, uint32_t x, uint32_t y) const {
    return cutStoredTile(levels[l], tile_px, border_px, x, y);
  }
};

PyramidTiles makePyramid(uint32_t width, uint32_t height, uint32_t channels, uint32_t tile_px,
                         uint32_t border_px, uint32_t seed) {
  PyramidTiles pyramid{tile_px, border_px, {makeLevel0(width, height, channels, seed)}};
  while (pyramid.levels.back().width_px > tile_px || pyramid.levels.back().height_px > tile_px)
    pyramid.levels.push_back(floorDownsample(pyramid.levels.back()));
  return pyramid;
}

ParentTexels parentOf(const Image& parent, uint32_t x, uint32_t y, uint32_t tile_px,
                      uint32_t border_px) {
  return {parent.view(), x & 1, y & 1, tile_px, border_px};
}

Image decodeOrDie(std::span<const uint8_t> payload, uint32_t side, uint32_t channels,
                  const ParentTexels* parent) {
  Image out(side, side, channels);
  auto decoded = decodeTile(Codec::kPtm, payload, out, parent);
  EXPECT_TRUE(decoded.has_value()) << decoded.error().message;
  return out;
}

TEST(PtmCodec, EveryLevelOfAFloorPyramidRoundTripsBitExactlyAgainstItsDecodedParent) {
  struct Case {
    uint32_t width, height, border;
  };
  for (const Case& c : {Case{200, 131, 0}, Case{129, 67, 1}, Case{157, 99, 3}, Case{64, 64, 2}}) {
    for (uint32_t channels = 1; channels <= 4; ++channels) {
      const uint32_t tile_px = 64, side = tile_px + 2 * c.border;
      PyramidTiles pyramid = makePyramid(c.width, c.height, channels, tile_px, c.border, channels);
      // Decode coarse to fine, each level against the previous level's *decoded* tiles, as a
      // reader does.
      std::vector<std::vector<Image>> decoded(pyramid.levels.size());
      for (uint32_t l = uint32_t(pyramid.levels.size()); l-- > 0;) {
        for (uint32_t y = 0; y < pyramid.tilesY(l); ++y) {
          for (uint32_t x = 0; x < pyramid.tilesX(l); ++x) {
            Image tile = pyramid.tile(l, x, y);
            std::optional<ParentTexels> parent;
            if (l + 1 < pyramid.levels.size())
              parent = parentOf(decoded[l + 1][(y / 2) * pyramid.tilesX(l + 1) + x / 2], x, y,
                                tile_px, c.border);
            auto payload = encodeTile(Codec::kPtm, tile.view(), {}, parent ? &*parent : nullptr);
            ASSERT_TRUE(payload.has_value()) << payload.error().message;
            EXPECT_EQ((*payload)[0],
                      uint8_t(parent ? Predictor::kParentNearest : Predictor::kRoot));
            Image out = decodeOrDie(*payload, side, channels, parent ? &*parent : nullptr);
            ASSERT_EQ(out.texels, tile.texels)
                << c.width << "x" << c.height << " border " << c.border << " channels " << channels
                << " tile (" << l << "," << x << "," << y << ")";
            decoded[l].push_back(std::move(out));
          }
        }
      }
    }
  }
}

TEST(PtmCodec, EveryPredictorRoundTripsAndTheParentMakesTilesSmaller) {
  PyramidTiles pyramid = makePyramid(256, 256, 3, 128, 1, 5);
  const Image parent_tile = pyramid.tile(1, 0, 0);
  const Image child = pyramid.tile(0, 1, 0);
  ParentTexels parent = parentOf(parent_tile, 1, 0, 128, 1);
  auto root = encodePtm(child.view(), {}, nullptr, Predictor::kRoot, PtmCoder::kZstd, nullptr);
  ASSERT_TRUE(root.has_value());
  for (Predictor predictor : {Predictor::kParentNearest, Predictor::kParentBilinear}) {
    auto payload = encodePtm(child.view(), {}, &parent, predictor, PtmCoder::kZstd, nullptr);
    ASSERT_TRUE(payload.has_value()) << payload.error().message;
    EXPECT_LT(payload->size(), root->size()) << int(predictor);
    EXPECT_EQ(decodeOrDie(*payload, child.width_px, 3, &parent).texels, child.texels);
  }
}

TEST(PtmCodec, ARemainderOutsideZeroToThreeStillDecodesExactly) {
  // A parent that is not the floor average of its children (as in a level's padding) makes
  // eq. 3's remainder any byte; modulo-256 arithmetic keeps the tile lossless.
  Image child = makeLevel0(66, 66, 4, 3);
  Image parent(66, 66, 4);
  uint32_t random = 99;
  for (uint8_t& v : parent.texels) v = uint8_t(nextRandom(random));
  ParentTexels texels = parentOf(parent, 1, 1, 64, 1);
  auto payload = encodeTile(Codec::kPtm, child.view(), {}, &texels);
  ASSERT_TRUE(payload.has_value());
  EXPECT_EQ(decodeOrDie(*payload, 66, 4, &texels).texels, child.texels);
}

struct ChildPayload {
  Image parent, child;
  std::vector<uint8_t> payload;
};

ChildPayload makeChildPayload(uint32_t channels) {
  PyramidTiles pyramid = makePyramid(120, 100, channels, 64, 1, 11);
  ChildPayload result{pyramid.tile(1, 0, 0), pyramid.tile(0, 1, 1), {}};
  ParentTexels parent = parentOf(result.parent, 1, 1, 64, 1);
  result.payload = *encodeTile(Codec::kPtm, result.child.view(), {}, &parent);
  return result;
}

TEST(PtmCodec, DecodeRejectsEveryTruncationAndTrailingBytes) {
  for (uint32_t channels = 1; channels <= 4; ++channels) {
    ChildPayload tile = makeChildPayload(channels);
    ParentTexels parent = parentOf(tile.parent, 1, 1, 64, 1);
    for (size_t length = 0; length < tile.payload.size(); ++length) {
      // A fresh allocation of exactly `length` bytes, so ASan catches any read past it.
      std::vector<uint8_t> prefix(tile.payload.begin(), tile.payload.begin() + length);
      Image out(66, 66, channels);
      auto decoded = decodeTile(Codec::kPtm, prefix, out, &parent);
      ASSERT_FALSE(decoded.has_value()) << "prefix " << length;
      EXPECT_EQ(decoded.error().code, ErrorCode::kCorrupt);
    }
    std::vector<uint8_t> longer = tile.payload;
    longer.push_back(0);
    Image out(66, 66, channels);
    auto decoded = decodeTile(Codec::kPtm, longer, out, &parent);
    ASSERT_FALSE(decoded.has_value());
    EXPECT_NE(decoded.error().message.find("trailing"), std::string::npos);
  }
}

TEST(PtmCodec, DecodeRejectsUnknownPredictorReservedByteAndAMissingParent) {
  ChildPayload tile = makeChildPayload(3);
  ParentTexels parent = parentOf(tile.parent, 1, 1, 64, 1);
  Image out(66, 66, 3);
  std::vector<uint8_t> bad = tile.payload;
  bad[0] = 3;
  EXPECT_FALSE(decodeTile(Codec::kPtm, bad, out, &parent).has_value());
  bad = tile.payload;
  bad[1] = 1;
  EXPECT_FALSE(decodeTile(Codec::kPtm, bad, out, &parent).has_value());
  auto orphan = decodeTile(Codec::kPtm, tile.payload, out, nullptr);
  ASSERT_FALSE(orphan.has_value());
  EXPECT_NE(orphan.error().message.find("parent"), std::string::npos);
}

TEST(PtmCodec, AParentThatDoesNotFitIsRefusedNotRead) {
  ChildPayload tile = makeChildPayload(3);
  Image small(40, 40, 3);
  ParentTexels parent = parentOf(small, 1, 1, 64, 1);
  Image out(66, 66, 3);
  auto decoded = decodeTile(Codec::kPtm, tile.payload, out, &parent);
  ASSERT_FALSE(decoded.has_value());
  EXPECT_EQ(decoded.error().code, ErrorCode::kInvalidArgument);
  Image gray(66, 66, 1);
  ParentTexels wrong_channels = parentOf(gray, 1, 1, 64, 1);
  EXPECT_FALSE(decodeTile(Codec::kPtm, tile.payload, out, &wrong_channels).has_value());
}

TEST(PtmCodec, SingleByteCorruptionNeverCrashesNorPoisonsTheScratch) {
  ChildPayload tile = makeChildPayload(4);
  ParentTexels parent = parentOf(tile.parent, 1, 1, 64, 1);
  CodecScratch scratch;
  for (size_t i = 0; i < tile.payload.size(); ++i) {
    std::vector<uint8_t> corrupt = tile.payload;
    corrupt[i] ^= uint8_t(1 + i % 255);
    Image out(66, 66, 4);
    (void)decodeTile(Codec::kPtm, corrupt, out, &parent, &scratch);
  }
  // The scratch carries nothing over: the intact payload still decodes exactly.
  Image out(66, 66, 4);
  ASSERT_TRUE(decodeTile(Codec::kPtm, tile.payload, out, &parent, &scratch).has_value());
  EXPECT_EQ(out.texels, tile.child.texels);
  // The codec cannot tell a wrong parent (that is the archive checksum's job); it decodes to
  // other texels without failing or reading out of range.
  Image other_parent = tile.parent;
  other_parent.texels[(size_t(40) * 66 + 40) * 4] ^= 0x55;  // inside the quadrant used
  ParentTexels wrong = parentOf(other_parent, 1, 1, 64, 1);
  ASSERT_TRUE(decodeTile(Codec::kPtm, tile.payload, out, &wrong).has_value());
  EXPECT_NE(out.texels, tile.child.texels);
}

}  // namespace
}  // namespace tessera::detail
