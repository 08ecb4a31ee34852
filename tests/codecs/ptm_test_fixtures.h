#pragma once
// Fixtures of the ptm codec tests (codec_ptm_test.cpp, codec_ptm_hostile_test.cpp): floor
// pyramids cut into tiles as the builder stores them, their parents, and the predictors and
// coders the sweeps cover.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "codecs/encode.h"
#include "ptm/ptm_encode.h"
#include "support/test_images.h"

namespace tessera::detail {

// A coder-7 payload of `recording` (a walk of coder 1's) with a table wherever one saves any
// bytes: the encoder sends only tables that save lanes::kTableMinGainBytes, which small tiles
// never do, and the decoders' tables need them.
inline std::vector<uint8_t> lanesPayloadWithAnyTables(const PtmRecording& recording) {
  return encodeRecordedPtm(recording, PtmCoder::kRansLanes, nullptr, nullptr, 0.0);
}

// A coder-7 payload of `recording` (a walk of coder 1's, 3 or 4 channels) with green-led
// contexts, and with `any_tables` a table wherever one saves any bytes.
inline std::vector<uint8_t> greenLedLanesPayload(const PtmRecording& recording,
                                                 bool any_tables = false) {
  PtmRecording led;
  leadRecordingByGreen(recording, led);
  return encodeRecordedPtm(led, PtmCoder::kRansLanes, nullptr, nullptr,
                           any_tables ? std::optional<double>(0.0) : std::nullopt);
}

// The coder a payload names, without its flags.
inline PtmCoder coderIn(std::span<const uint8_t> payload) {
  return PtmCoder(payload[1] & uint8_t(~(kPtmTablesFlag | kPtmGreenLedFlag)));
}
inline bool hasTables(std::span<const uint8_t> payload) {
  return (payload[1] & kPtmTablesFlag) != 0;
}
inline bool isGreenLed(std::span<const uint8_t> payload) {
  return (payload[1] & kPtmGreenLedFlag) != 0;
}

// Smooth shading, an edge and noise: residuals that are neither all zero nor all random.
inline Image makeLevel0(uint32_t width, uint32_t height, uint32_t channels, uint32_t seed) {
  Image image(width, height, channels);
  uint32_t random = seed * 2654435761u + 7;
  for (uint32_t y = 0; y < height; ++y)
    for (uint32_t x = 0; x < width; ++x)
      for (uint32_t c = 0; c < channels; ++c) {
        int value = int(128 + 90 * std::sin(x * 0.05 + c) * std::cos(y * 0.03)) +
                    (x > width / 2 ? 40 : 0) + int(test::nextRandom(random) % 9) - 4;
        image.row(y)[size_t(x) * channels + c] = uint8_t(std::clamp(value, 0, 255));
      }
  return image;
}

// The pyramid step ptm requires, written independently of src/build: floor of the 2x2 sum
// over the level extended by replicating its last row and column.
inline Image floorDownsample(const Image& level) {
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
inline Image cutStoredTile(const Image& level, uint32_t tile_px, uint32_t border_px, uint32_t x,
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

// `step` > 1 rounds level 0's texels down to its multiples: residuals on a comb, as a palette's
// steps leave them, which no family model fits and explicit tables do.
inline PyramidTiles makePyramid(uint32_t width, uint32_t height, uint32_t channels,
                                uint32_t tile_px, uint32_t border_px, uint32_t seed,
                                uint32_t step = 1) {
  PyramidTiles pyramid{tile_px, border_px, {makeLevel0(width, height, channels, seed)}};
  for (uint8_t& texel : pyramid.levels[0].texels) texel = uint8_t(texel / step * step);
  while (pyramid.levels.back().width_px > tile_px || pyramid.levels.back().height_px > tile_px)
    pyramid.levels.push_back(floorDownsample(pyramid.levels.back()));
  return pyramid;
}

// Colour that errs together, 256 x 256 in 128-px tiles: smooth shading, and in a random third
// of the texels noise in every channel at once. A texel's neighbours cannot tell whether it is
// noisy, and its green residual can: red's and blue's residuals are large where green's is
// and mostly zero where it is zero (coder 7's green-led contexts).
inline PyramidTiles makeColourThatErrsTogether(uint32_t seed) {
  PyramidTiles pyramid = makePyramid(256, 256, 3, 128, 0, seed);
  Image& base = pyramid.levels[0];
  for (uint32_t y = 0; y < 256; ++y)
    for (uint32_t x = 0; x < 256; ++x) {
      const bool noisy = test::nextRandom(seed) % 3 == 0;
      for (uint32_t c = 0; c < 3; ++c) {
        const int noise = noisy ? int(test::nextRandom(seed) % 25) - 12 : 0;
        const int smooth = int(60 + 40 * c + x / 3 + y / 5);
        base.row(y)[size_t(x) * 3 + c] = uint8_t(std::clamp(smooth + noise, 0, 255));
      }
    }
  for (size_t l = 1; l < pyramid.levels.size(); ++l)
    pyramid.levels[l] = floorDownsample(pyramid.levels[l - 1]);
  return pyramid;
}

inline ParentTexels parentOf(const Image& parent, uint32_t x, uint32_t y, uint32_t tile_px,
                             uint32_t border_px) {
  return {parent.view(), x & 1, y & 1, tile_px, border_px};
}

inline Image decodeOrDie(std::span<const uint8_t> payload, uint32_t side, uint32_t channels,
                         const ParentTexels* parent) {
  Image out(side, side, channels);
  auto decoded = decodeTile(Codec::kPtm, payload, out, parent);
  EXPECT_TRUE(decoded.has_value()) << decoded.error().message;
  return out;
}

// Codes every tile of `pyramid` with `encode(tile, parent)` and decodes coarse to fine, each
// level against the previous level's *decoded* tiles, as a reader does; every texel must come
// back. `what` names the case in failures.
template <class Encode>
inline void expectCoarseToFineRoundTrip(const PyramidTiles& pyramid, uint32_t channels,
                                        Encode&& encode, const std::string& what) {
  const uint32_t side = pyramid.tile_px + 2 * pyramid.border_px;
  std::vector<std::vector<Image>> decoded(pyramid.levels.size());
  for (uint32_t l = uint32_t(pyramid.levels.size()); l-- > 0;) {
    for (uint32_t y = 0; y < pyramid.tilesY(l); ++y) {
      for (uint32_t x = 0; x < pyramid.tilesX(l); ++x) {
        Image tile = pyramid.tile(l, x, y);
        std::optional<ParentTexels> parent;
        if (l + 1 < pyramid.levels.size())
          parent = parentOf(decoded[l + 1][(y / 2) * pyramid.tilesX(l + 1) + x / 2], x, y,
                            pyramid.tile_px, pyramid.border_px);
        const ParentTexels* parent_texels = parent ? &*parent : nullptr;
        Result<std::vector<uint8_t>> payload = encode(tile, parent_texels);
        ASSERT_TRUE(payload.has_value()) << payload.error().message;
        Image out = decodeOrDie(*payload, side, channels, parent_texels);
        ASSERT_EQ(out.texels, tile.texels) << what << " tile (" << l << "," << x << "," << y << ")";
        decoded[l].push_back(std::move(out));
      }
    }
  }
}

inline constexpr Predictor kParentPredictors[] = {
    Predictor::kParentNearest, Predictor::kNeighbourMedian, Predictor::kParentCorrected,
    Predictor::kLeastSquares};
inline constexpr PtmCoder kCoders[] = {PtmCoder::kZstd,
                                       PtmCoder::kRans,
                                       PtmCoder::kRansChained,
                                       PtmCoder::kRansMixture,
                                       PtmCoder::kRansMixtureChained,
                                       PtmCoder::kRansParentErrors};
inline constexpr PtmCoder kRansCoders[] = {PtmCoder::kRans, PtmCoder::kRansChained,
                                           PtmCoder::kRansMixture, PtmCoder::kRansMixtureChained,
                                           PtmCoder::kRansParentErrors};

}  // namespace tessera::detail
