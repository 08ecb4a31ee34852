// ptm coded against its parent: whole pyramids of the integer floor average (Marvie &
// Bouatouch, eq. 3) round-trip bit-exactly tile by tile, coarse to fine, for odd sizes, every
// channel count and odd and even borders, and each predictor and coder earns its place.
// Hostile payloads are in codec_ptm_hostile_test.cpp; coding without a parent is covered with
// the other codecs in codec_test.cpp.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <initializer_list>
#include <optional>
#include <span>
#include <vector>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include "codecs/encode.h"
#include "ptm/ptm_encode.h"
#include "ptm/ptm_least_squares_fit.h"
#include "ptm/ptm_walk.h"
#include "ptm_test_fixtures.h"
#include "support/test_images.h"

namespace tessera::detail {
namespace {

using test::nextRandom;

TEST(PtmCodec, EveryLevelOfAFloorPyramidRoundTripsBitExactlyAgainstItsDecodedParent) {
  struct Case {
    uint32_t width, height, border;
  };
  for (const Case& c : {Case{200, 131, 0}, Case{129, 67, 1}, Case{157, 99, 3}, Case{64, 64, 2}}) {
    for (uint32_t channels = 1; channels <= 4; ++channels) {
      PyramidTiles pyramid = makePyramid(c.width, c.height, channels, 64, c.border, channels);
      expectCoarseToFineRoundTrip(
          pyramid, channels,
          [](const Image& tile, const ParentTexels* parent) {
            auto payload = encodeTile(Codec::kPtm, tile.view(), {}, parent);
            if (payload) {
              EXPECT_EQ((*payload)[0] == uint8_t(Predictor::kRoot), parent == nullptr);
              EXPECT_TRUE(isRansCoder(coderIn(*payload)));
            }
            return payload;
          },
          fmt::format("{}x{} border {} channels {}", c.width, c.height, c.border, channels));
    }
  }
}

// What the default encoder must write, by the rule docs/codecs.md states: the predictor (of
// nearest parent, neighbour median and parent-corrected) that coder 6 codes in the fewest bytes,
// or, where that is the neighbour median, least squares if coder 6 codes it at least 3 %
// smaller; then of coder 7 (lanes; not for predictor 5 with predictor 4's estimate) and coders
// 1 to 4 (fastest to decode first) the first whose size estimate is within 3 % of coder 6's,
// else coder 6.
std::vector<uint8_t> expectedDefaultPayload(const Image& tile, const ParentTexels* parent) {
  Predictor predictor = Predictor::kRoot;
  size_t reference = SIZE_MAX;
  for (Predictor candidate :
       {Predictor::kParentNearest, Predictor::kNeighbourMedian, Predictor::kParentCorrected}) {
    const size_t bytes =
        *estimatePtmBytes(tile.view(), {}, parent, candidate, PtmCoder::kRansParentErrors, nullptr);
    if (bytes < reference) {
      predictor = parent != nullptr ? candidate : Predictor::kRoot;
      reference = bytes;
    }
  }
  // Predictor 5's weights: without predictor 4's estimate where they code no larger.
  PtmLeastSquaresFit fit;
  if (predictor == Predictor::kNeighbourMedian) {
    const size_t fitted = *estimatePtmBytes(tile.view(), {}, parent, Predictor::kLeastSquares,
                                            PtmCoder::kRansParentErrors, nullptr);
    if (fitted * 100 <= reference * 97) {
      predictor = Predictor::kLeastSquares;
      reference = fitted;
      fit.without_estimate = true;
      const size_t without = *estimatePtmBytes(tile.view(), {}, parent, Predictor::kLeastSquares,
                                               PtmCoder::kRansParentErrors, nullptr, &fit);
      if (without <= reference)
        reference = without;
      else
        fit.without_estimate = false;
    }
  }
  const PtmCoder by_speed[] = {PtmCoder::kRansLanes, PtmCoder::kRans, PtmCoder::kRansChained,
                               PtmCoder::kRansMixture, PtmCoder::kRansMixtureChained};
  PtmCoder chosen = PtmCoder::kRansParentErrors;
  for (PtmCoder coder : by_speed) {
    if (coder == PtmCoder::kRansLanes && predictor == Predictor::kLeastSquares &&
        !fit.without_estimate)
      continue;
    if (*estimatePtmBytes(tile.view(), {}, parent, predictor, coder, nullptr, &fit) * 100 <=
        reference * 103) {
      chosen = coder;
      break;
    }
  }
  return *encodePtm(tile.view(), {}, parent, predictor, chosen, nullptr, &fit);
}

TEST(PtmCodec, EveryPredictorWithEveryCoderRoundTripsWholePyramidsBitExactly) {
  struct Case {
    uint32_t width, height, border;
  };
  for (const Case& c : {Case{133, 77, 0}, Case{97, 130, 1}, Case{71, 69, 2}, Case{101, 99, 3}}) {
    for (uint32_t channels = 1; channels <= 4; ++channels) {
      PyramidTiles pyramid = makePyramid(c.width, c.height, channels, 32, c.border, channels + 7);
      for (PtmCoder coder : kCoders) {
        for (Predictor predictor : kParentPredictors) {
          expectCoarseToFineRoundTrip(
              pyramid, channels,
              [&](const Image& tile, const ParentTexels* parent) {
                auto payload = encodePtm(tile.view(), {}, parent, predictor, coder, nullptr);
                if (payload) {
                  EXPECT_EQ((*payload)[0], uint8_t(parent ? predictor : Predictor::kRoot));
                  EXPECT_EQ(coderIn(*payload), coder);
                }
                return payload;
              },
              fmt::format("{}x{} border {} channels {} predictor {} coder {}", c.width, c.height,
                          c.border, channels, int(predictor), int(coder)));
        }
      }
    }
  }
}

TEST(PtmCodec, EffortSelectsTheEncoderModeAndEveryModeRoundTrips) {
  PyramidTiles pyramid = makePyramid(256, 256, 3, 128, 0, 5);
  const Image parent_tile = pyramid.tile(1, 0, 0);
  const Image child = pyramid.tile(0, 1, 0);
  ParentTexels parent = parentOf(parent_tile, 1, 0, 128, 0);
  auto payloadAt = [&](int effort) {
    EncodeOptions options;
    options.effort = effort;
    auto payload = encodeTile(Codec::kPtm, child.view(), options, &parent);
    EXPECT_TRUE(payload.has_value()) << payload.error().message;
    EXPECT_EQ(decodeOrDie(*payload, 128, 3, &parent).texels, child.texels) << "effort " << effort;
    return *payload;
  };
  // Byte 0 is the predictor, byte 1 the coder (0 zstd, 1-7 rANS: docs/codecs.md).
  const std::vector<uint8_t> fast = payloadAt(1);
  EXPECT_EQ(fast[0], uint8_t(Predictor::kParentNearest));
  EXPECT_EQ(fast[1], uint8_t(PtmCoder::kZstd));
  // Effort 2: the smaller of effort 1's payload and coder 7's, whose predictor is the smaller
  // of 3 and 1 by estimate; where 3 won and came out below effort 1's size, 5 without
  // predictor 4's estimate if its estimate is at least 2 % below that; then 4 if its estimate
  // is at least 25 % below the choice; then the choice with green-led contexts if their
  // estimate is at least 2 % below it.
  const std::vector<uint8_t> smaller = payloadAt(2);
  auto lanesWith = [&](Predictor predictor) {
    auto payload = encodePtm(child.view(), {}, &parent, predictor, PtmCoder::kRansLanes, nullptr);
    auto estimate =
        estimatePtmBytes(child.view(), {}, &parent, predictor, PtmCoder::kRansLanes, nullptr);
    EXPECT_TRUE(payload.has_value() && estimate.has_value());
    return std::pair(*payload, *estimate);
  };
  const auto [median, median_estimate] = lanesWith(Predictor::kNeighbourMedian);
  const auto [nearest, nearest_estimate] = lanesWith(Predictor::kParentNearest);
  const auto [corrected, corrected_estimate] = lanesWith(Predictor::kParentCorrected);
  const auto [plain, plain_estimate] = lanesWith(Predictor::kLeastSquares);
  const bool median_won = median_estimate <= nearest_estimate;
  const std::vector<uint8_t>* lanes = median_won ? &median : &nearest;
  Predictor choice = median_won ? Predictor::kNeighbourMedian : Predictor::kParentNearest;
  size_t lanes_estimate = std::min(median_estimate, nearest_estimate);
  auto takeIfItSaves = [&](const std::vector<uint8_t>& candidate, size_t estimate, size_t percent,
                           Predictor candidate_choice) {
    if (estimate * 100 > lanes_estimate * (100 - percent)) return;
    lanes = &candidate;
    lanes_estimate = estimate;
    choice = candidate_choice;
  };
  if (median_won && lanes_estimate < fast.size())
    takeIfItSaves(plain, plain_estimate, 2, Predictor::kLeastSquares);
  takeIfItSaves(corrected, corrected_estimate, 25, Predictor::kParentCorrected);
  PtmRecording recording, led;
  ASSERT_TRUE(
      recordPtm(child.view(), &parent, choice, PtmCoder::kRansLanes, nullptr, nullptr, recording)
          .has_value());
  leadRecordingByGreen(recording, led);
  const std::vector<uint8_t> led_payload = encodeRecordedPtm(led, PtmCoder::kRansLanes, nullptr);
  takeIfItSaves(led_payload, estimateRecordedPtm(led, PtmCoder::kRansLanes), 2, choice);
  EXPECT_EQ(smaller, lanes->size() < fast.size() ? *lanes : fast);
  // The default: the predictor that suits coder 6 best, and then the fastest coder within 3 %
  // of coder 6. Effort 3 and above are the default (format 1.0 removed effort 3's own mode).
  const std::vector<uint8_t> smallest = payloadAt(0);
  EXPECT_EQ(smallest, expectedDefaultPayload(child, &parent));
  EXPECT_EQ(payloadAt(3), smallest);
  EXPECT_EQ(payloadAt(9), smallest);
  EXPECT_LE(smaller.size(), fast.size());
}

// Tile (1, 1) of level 0 of a pyramid, its parent (tile (0, 0) of level 1) and effort 2's
// payload of it.
struct EffortTwoTile {
  Image parent_tile, child;
  Result<std::vector<uint8_t>> payload;
  ParentTexels parent() const { return parentOf(parent_tile, 1, 1, 128, 0); }
};

// Rebuilds `pyramid`'s levels from its base and codes tile (1, 1) of level 0 with effort 2.
EffortTwoTile effortTwoTile(PyramidTiles& pyramid) {
  for (size_t l = 1; l < pyramid.levels.size(); ++l)
    pyramid.levels[l] = floorDownsample(pyramid.levels[l - 1]);
  EffortTwoTile tile{pyramid.tile(1, 0, 0), pyramid.tile(0, 1, 1), std::vector<uint8_t>{}};
  const ParentTexels parent = tile.parent();
  EncodeOptions options;
  options.effort = 2;
  tile.payload = encodeTile(Codec::kPtm, tile.child.view(), options, &parent);
  return tile;
}

// Expects effort 2 to code tile (1, 1) of level 0 of `pyramid` with coder 7 and `expected`, at
// least `percent` % smaller than coder 7 with each of `others`; with predictor 5, without
// predictor 4's estimate, the only weights coder 7 has.
void expectEffortTwoTakesTheLanesWith(PyramidTiles& pyramid, Predictor expected,
                                      std::initializer_list<Predictor> others, size_t percent) {
  const EffortTwoTile tile = effortTwoTile(pyramid);
  const Image& child = tile.child;
  const ParentTexels parent = tile.parent();
  const auto& payload = tile.payload;
  ASSERT_TRUE(payload.has_value());
  EXPECT_EQ((*payload)[0], uint8_t(expected));
  EXPECT_EQ(coderIn(*payload), PtmCoder::kRansLanes);
  for (Predictor other : others) {
    auto payload_with = encodePtm(child.view(), {}, &parent, other, PtmCoder::kRansLanes, nullptr);
    ASSERT_TRUE(payload_with.has_value());
    EXPECT_LE(payload->size() * 100, payload_with->size() * (100 - percent)) << int(other);
  }
  EXPECT_EQ(decodeOrDie(*payload, 128, 3, &parent).texels, child.texels);
  if (expected != Predictor::kLeastSquares) return;
  EXPECT_FALSE(
      usesEstimate(reinterpret_cast<const int8_t*>(payload->data() + ptm::kHeaderBytes), 3));
}

// Smooth waves of `period` texels with noise of 0..noise-1 levels.
PyramidTiles makeWavesWithNoise(double period, uint32_t noise) {
  PyramidTiles pyramid = makePyramid(256, 256, 3, 128, 0, 7);
  uint32_t seed = 11;
  Image& base = pyramid.levels[0];
  for (uint32_t y = 0; y < base.height_px; ++y)
    for (uint32_t x = 0; x < base.width_px; ++x)
      for (uint32_t c = 0; c < 3; ++c)
        base.row(y)[x * 3 + c] =
            uint8_t(120 + 90 * std::sin(x / (period + c)) * std::cos(y / (period + 2)) +
                    nextRandom(seed) % noise);
  return pyramid;
}

TEST(PtmCodec, EffortTwoTakesGreenLedContextsWhereTheyPay) {
  // Colour that errs together (makeColourThatErrsTogether): effort 2 codes the tile with
  // green-led contexts; on waves whose channels carry noise of their own, without.
  for (const bool errs_together : {true, false}) {
    PyramidTiles pyramid =
        errs_together ? makeColourThatErrsTogether(23) : makeWavesWithNoise(40, 9);
    const EffortTwoTile tile = effortTwoTile(pyramid);
    const ParentTexels parent = tile.parent();
    ASSERT_TRUE(tile.payload.has_value());
    EXPECT_EQ(coderIn(*tile.payload), PtmCoder::kRansLanes);
    EXPECT_EQ(isGreenLed(*tile.payload), errs_together);
    EXPECT_EQ(decodeOrDie(*tile.payload, 128, 3, &parent).texels, tile.child.texels);
  }
}

TEST(PtmCodec, EffortTwoTakesTheParentCorrectedLanesWhereTheyPay) {
  // Short waves with faint noise, which the upsampled parent predicts better than the
  // neighbours do: effort 2 takes predictor 4 with coder 7 over the median with it.
  PyramidTiles pyramid = makeWavesWithNoise(1.5, 1);
  expectEffortTwoTakesTheLanesWith(pyramid, Predictor::kParentCorrected,
                                   {Predictor::kNeighbourMedian}, 25);
}

// A noisy source enlarged twice: its columns by repeating texels, its rows by averaging the
// two rows around each new one. The median sees the repeats but not the row below that each
// averaged row leans on; the parent knows the block's mean but not the repeats; predictor 5's
// fit takes from both.
PyramidTiles makeEnlargedNoise() {
  Image noise(128, 128, 3);
  uint32_t seed = 5;
  for (uint8_t& texel : noise.texels) texel = uint8_t(nextRandom(seed));
  PyramidTiles pyramid = makePyramid(256, 256, 3, 128, 0, 7);
  Image& base = pyramid.levels[0];
  for (uint32_t y = 0; y < 256; ++y) {
    const uint8_t* upper = noise.row(std::min(y / 2, 126u));
    const uint8_t* lower = noise.row(std::min(y / 2, 126u) + 1);
    const int below = int(y % 2);
    for (uint32_t x = 0; x < 256; ++x)
      for (uint32_t c = 0; c < 3; ++c) {
        const size_t at = (x / 2) * 3 + c;
        base.row(y)[x * 3 + c] = uint8_t(((2 - below) * upper[at] + below * lower[at] + 1) / 2);
      }
  }
  return pyramid;
}

TEST(PtmCodec, EffortTwoTakesTheLeastSquaresLanesWhereTheyPay) {
  // Effort 2 takes predictor 5 with coder 7, without predictor 4's estimate.
  PyramidTiles pyramid = makeEnlargedNoise();
  expectEffortTwoTakesTheLanesWith(pyramid, Predictor::kLeastSquares,
                                   {Predictor::kNeighbourMedian, Predictor::kParentCorrected}, 2);
}

TEST(PtmCodec, TheDefaultTakesLeastSquaresWithoutTheEstimateWhereItCodesNoLarger) {
  PyramidTiles pyramid = makeEnlargedNoise();
  for (size_t l = 1; l < pyramid.levels.size(); ++l)
    pyramid.levels[l] = floorDownsample(pyramid.levels[l - 1]);
  const Image parent_tile = pyramid.tile(1, 0, 0);
  const Image child = pyramid.tile(0, 1, 1);
  ParentTexels parent = parentOf(parent_tile, 1, 1, 128, 0);
  auto payload = encodeTile(Codec::kPtm, child.view(), {}, &parent);
  ASSERT_TRUE(payload.has_value());
  EXPECT_EQ(*payload, expectedDefaultPayload(child, &parent));
  ASSERT_EQ((*payload)[0], uint8_t(Predictor::kLeastSquares));
  EXPECT_FALSE(
      usesEstimate(reinterpret_cast<const int8_t*>(payload->data() + ptm::kHeaderBytes), 3));
  EXPECT_EQ(decodeOrDie(*payload, 128, 3, &parent).texels, child.texels);
}

TEST(PtmCodec, EveryPredictorRoundTripsAndTheParentMakesTilesSmaller) {
  PyramidTiles pyramid = makePyramid(256, 256, 3, 128, 1, 5);
  const Image parent_tile = pyramid.tile(1, 0, 0);
  const Image child = pyramid.tile(0, 1, 0);
  ParentTexels parent = parentOf(parent_tile, 1, 0, 128, 1);
  auto root = encodePtm(child.view(), {}, nullptr, Predictor::kRoot, PtmCoder::kZstd, nullptr);
  ASSERT_TRUE(root.has_value());
  for (Predictor predictor : kParentPredictors) {
    auto payload = encodePtm(child.view(), {}, &parent, predictor, PtmCoder::kZstd, nullptr);
    ASSERT_TRUE(payload.has_value()) << payload.error().message;
    EXPECT_LT(payload->size(), root->size()) << int(predictor);
    EXPECT_EQ(decodeOrDie(*payload, child.width_px, 3, &parent).texels, child.texels);
  }
  for (PtmCoder coder : kRansCoders) {
    auto rans_root = encodePtm(child.view(), {}, nullptr, Predictor::kRoot, coder, nullptr);
    ASSERT_TRUE(rans_root.has_value());
    for (Predictor predictor :
         {Predictor::kParentNearest, Predictor::kNeighbourMedian, Predictor::kParentCorrected}) {
      auto payload = encodePtm(child.view(), {}, &parent, predictor, coder, nullptr);
      ASSERT_TRUE(payload.has_value()) << payload.error().message;
      EXPECT_LT(payload->size(), rans_root->size()) << int(predictor) << " coder " << int(coder);
      EXPECT_EQ(decodeOrDie(*payload, child.width_px, 3, &parent).texels, child.texels);
    }
  }
}

// A 64x64 RGB tile whose texels are either flat grey or carry independent noise in every
// channel, scattered so that the neighbourhood's activity cannot tell which: only the residual
// already coded in the same texel can.
Image makeTileWhoseChannelsErrTogether(uint32_t seed) {
  Image tile(64, 64, 3);
  uint32_t random = seed;
  for (size_t i = 0; i < tile.texels.size(); i += 3) {
    const bool noisy = nextRandom(random) % 4 == 0;
    for (size_t c = 0; c < 3; ++c)
      tile.texels[i + c] = uint8_t(noisy ? 128 + int(nextRandom(random) % 41) - 20 : 128);
  }
  return tile;
}

TEST(PtmCodec, ChainedContextsPayOffWhereColourChannelsErrTogether) {
  // Coders 2 and 4 code green first and let its residual choose the others' contexts.
  const Image tile = makeTileWhoseChannelsErrTogether(17);
  const std::pair<PtmCoder, PtmCoder> pairs[] = {
      {PtmCoder::kRans, PtmCoder::kRansChained},
      {PtmCoder::kRansMixture, PtmCoder::kRansMixtureChained}};
  for (auto [plain, chaining] : pairs) {
    auto per_channel = encodePtm(tile.view(), {}, nullptr, Predictor::kRoot, plain, nullptr);
    auto chained = encodePtm(tile.view(), {}, nullptr, Predictor::kRoot, chaining, nullptr);
    ASSERT_TRUE(per_channel.has_value());
    ASSERT_TRUE(chained.has_value());
    EXPECT_LT(chained->size() * 10, per_channel->size() * 9)
        << chained->size() << " against " << per_channel->size();
    EXPECT_EQ(decodeOrDie(*chained, 64, 3, nullptr).texels, tile.texels);
  }
}

// A 64x64 RGB tile of smooth slopes, which the median predicts exactly, beside patches of
// noise whose gradients are as large on average: activity alone puts both in the same classes;
// the errors coded next to a texel tell them apart.
Image makeTileOfSlopesBesideNoise(uint32_t seed) {
  Image tile(64, 64, 3);
  uint32_t random = seed;
  for (uint32_t y = 0; y < 64; ++y)
    for (uint32_t x = 0; x < 64; ++x) {
      const bool slope = (x / 16) % 2 == 0 || (y / 16) % 2 == 0;
      for (uint32_t c = 0; c < 3; ++c) {
        const uint32_t noise = nextRandom(random) % 15;
        tile.texels[(size_t(y) * 64 + x) * 3 + c] =
            uint8_t(slope ? 40 + 6 * (x % 16) + 3 * (15 - y % 16) + 10 * c : 120 + 10 * c + noise);
      }
    }
  return tile;
}

TEST(PtmCodec, ErrorActivityPaysOffWhereSmoothSlopesMeetNoise) {
  // Without a parent coder 6 is coder 4 with the neighbours' coded errors in the activity.
  const Image tile = makeTileOfSlopesBesideNoise(29);
  auto without =
      encodePtm(tile.view(), {}, nullptr, Predictor::kRoot, PtmCoder::kRansMixtureChained, nullptr);
  auto with =
      encodePtm(tile.view(), {}, nullptr, Predictor::kRoot, PtmCoder::kRansParentErrors, nullptr);
  ASSERT_TRUE(without.has_value());
  ASSERT_TRUE(with.has_value());
  // Chaining already separates the later channels of a texel; the gain is the first one's.
  EXPECT_LT(with->size() * 100, without->size() * 95)
      << with->size() << " against " << without->size();
  EXPECT_EQ(decodeOrDie(*with, 64, 3, nullptr).texels, tile.texels);
}

// A 128x128 level 0: a flat, gently shaded field with one 2x2 block in 16 of noise, and its
// floor average. Inside a tile a noisy block starts without warning from the texels decoded
// before it (its first texel has quiet neighbours), but not from its parent texel.
struct SmallPyramid {
  Image child, parent;
};
SmallPyramid makeIsolatedNoisyBlocks(uint32_t seed) {
  Image level0(128, 128, 3);
  uint32_t random = seed;
  std::vector<bool> noisy(64 * 64);
  for (size_t i = 0; i < noisy.size(); ++i) noisy[i] = nextRandom(random) % 16 == 0;
  for (uint32_t y = 0; y < 128; ++y)
    for (uint32_t x = 0; x < 128; ++x)
      for (uint32_t c = 0; c < 3; ++c)
        level0.texels[(size_t(y) * 128 + x) * 3 + c] = uint8_t(
            noisy[(y / 2) * 64 + x / 2] ? 60 + nextRandom(random) % 41 : 100 + 10 * c + x / 8);
  return {cutStoredTile(level0, 64, 0, 1, 1), floorDownsample(level0)};
}

TEST(PtmCodec, ParentActivityPaysOffWhereNoisyBlocksStartWithoutWarning) {
  // Coder 6 is coder 4 with the parent's gradients, the coded errors and each prediction's
  // distance from its parent texel in the activity.
  const SmallPyramid pyramid = makeIsolatedNoisyBlocks(37);
  const ParentTexels parent = parentOf(pyramid.parent, 1, 1, 64, 0);
  for (Predictor predictor : {Predictor::kNeighbourMedian, Predictor::kParentCorrected}) {
    auto errors = encodePtm(pyramid.child.view(), {}, &parent, predictor,
                            PtmCoder::kRansMixtureChained, nullptr);
    auto with_parent = encodePtm(pyramid.child.view(), {}, &parent, predictor,
                                 PtmCoder::kRansParentErrors, nullptr);
    ASSERT_TRUE(errors.has_value());
    ASSERT_TRUE(with_parent.has_value());
    EXPECT_LT(with_parent->size() * 100, errors->size() * 97)
        << int(predictor) << ": " << with_parent->size() << " against " << errors->size();
    EXPECT_EQ(decodeOrDie(*with_parent, 64, 3, &parent).texels, pyramid.child.texels);
  }
  // The default takes coder 6 there.
  auto by_default = encodeTile(Codec::kPtm, pyramid.child.view(), {}, &parent);
  ASSERT_TRUE(by_default.has_value());
  EXPECT_EQ(coderIn(*by_default), PtmCoder::kRansParentErrors);
  EXPECT_EQ(*by_default, expectedDefaultPayload(pyramid.child, &parent));
}

// Level 0 of a smooth field plus an offset per 2x2 block: the parent knows each block's offset,
// which no neighbour of the block's first texel shows, while the median follows the field
// inside the block. Only a prediction that weighs both does well.
SmallPyramid makeBlockOffsetsOnASlope(uint32_t seed, int spread) {
  Image level0(128, 128, 3);
  uint32_t random = seed;
  std::vector<int> offsets(64 * 64);
  for (int& offset : offsets) offset = int(nextRandom(random) % uint32_t(2 * spread + 1)) - spread;
  for (uint32_t y = 0; y < 128; ++y)
    for (uint32_t x = 0; x < 128; ++x)
      for (uint32_t c = 0; c < 3; ++c) {
        const int value =
            60 + int(x) / 2 + int(y) / 3 + 10 * int(c) + offsets[(y / 2) * 64 + x / 2];
        level0.row(y)[size_t(x) * 3 + c] = uint8_t(std::clamp(value, 0, 255));
      }
  return {cutStoredTile(level0, 64, 0, 1, 1), floorDownsample(level0)};
}

TEST(PtmCodec, LeastSquaresPaysOffWhereTheParentKnowsWhatNoNeighbourShows) {
  const SmallPyramid pyramid = makeBlockOffsetsOnASlope(43, 12);
  const ParentTexels parent = parentOf(pyramid.parent, 1, 1, 64, 0);
  auto fitted = encodePtm(pyramid.child.view(), {}, &parent, Predictor::kLeastSquares,
                          PtmCoder::kRansParentErrors, nullptr);
  ASSERT_TRUE(fitted.has_value());
  EXPECT_EQ(decodeOrDie(*fitted, 64, 3, &parent).texels, pyramid.child.texels);
  for (Predictor predictor :
       {Predictor::kParentNearest, Predictor::kNeighbourMedian, Predictor::kParentCorrected}) {
    auto other = encodePtm(pyramid.child.view(), {}, &parent, predictor,
                           PtmCoder::kRansParentErrors, nullptr);
    ASSERT_TRUE(other.has_value());
    EXPECT_LT(fitted->size() * 100, other->size() * 97)
        << int(predictor) << ": " << fitted->size() << " against " << other->size();
  }
  // The default fits predictor 5 only where the median wins the first round (on this tile the
  // nearest parent does), and writes what its rule says.
  auto by_default = encodeTile(Codec::kPtm, pyramid.child.view(), {}, &parent);
  ASSERT_TRUE(by_default.has_value());
  EXPECT_EQ(*by_default, expectedDefaultPayload(pyramid.child, &parent));
  // The weights travel in the payload: a changed weight changes the predictions, which either
  // fails the rANS stream's end check or gives other texels, and a fit passed in is used as is.
  std::vector<uint8_t> changed = *fitted;
  changed[2 + 4] = uint8_t(changed[2 + 4] + 40);  // position 0, channel 0, the parent term
  Image out(64, 64, 3);
  auto decoded = decodeTile(Codec::kPtm, changed, out, &parent);
  if (decoded.has_value()) {
    EXPECT_NE(out.texels, pyramid.child.texels);
  }
  PtmLeastSquaresFit fit;
  auto first = encodePtm(pyramid.child.view(), {}, &parent, Predictor::kLeastSquares,
                         PtmCoder::kZstd, nullptr, &fit);
  ASSERT_TRUE(first.has_value());
  EXPECT_TRUE(fit.fitted);
  EXPECT_TRUE(std::equal(first->begin() + 2, first->begin() + 2 + 4 * 3 * 9, fitted->begin() + 2));
  fit.weights[4] = 0;
  auto forced = encodePtm(pyramid.child.view(), {}, &parent, Predictor::kLeastSquares,
                          PtmCoder::kZstd, nullptr, &fit);
  ASSERT_TRUE(forced.has_value());
  EXPECT_EQ((*forced)[2 + 4], 0);
  EXPECT_EQ(decodeOrDie(*forced, 64, 3, &parent).texels, pyramid.child.texels);
  // Cut inside the weights: named as such.
  std::vector<uint8_t> cut(fitted->begin(), fitted->begin() + 20);
  auto short_weights = decodeTile(Codec::kPtm, cut, out, &parent);
  ASSERT_FALSE(short_weights.has_value());
  EXPECT_NE(short_weights.error().message.find("predictor weights"), std::string::npos);
}

TEST(PtmCodec, LeastSquaresFactoredPredictionIsTheSumOfItsTerms) {
  // The walk predicts with the median factored out of the sum; the fit and the payload's
  // meaning are the terms'. Any weights, texels and estimates, extremes included.
  uint32_t state = 17;
  const int8_t extremes[] = {-128, -1, 0, 1, 127};
  for (int round = 0; round < 100000; ++round) {
    int8_t weights[kLsTerms];
    int weight_sum = 0;
    for (int8_t& w : weights) {
      w = round % 3 == 0 ? extremes[nextRandom(state) % 5] : int8_t(nextRandom(state));
      weight_sum += w;
    }
    // The texel at the centre of a 3-wide, 2-high window; the parent's four texels apart.
    uint8_t window[6], parents[4];
    for (uint8_t& t : window)
      t = round % 5 == 0 ? uint8_t(255 * (nextRandom(state) & 1)) : uint8_t(nextRandom(state));
    for (uint8_t& t : parents) t = uint8_t(nextRandom(state));
    const bool origin = round % 7 == 0;
    const LsTexels texels{window + 4, -1,          -3,          -4,          -2,
                          origin,     &parents[0], &parents[1], &parents[2], &parents[3]};
    const uint8_t* texel = texels.texel;
    const int median = origin ? 0 : ptm::medPredict(texel[-1], texel[-3], texel[-4]);
    const int estimate16 = int(nextRandom(state) % 4700) - 300;
    int terms[kLsTerms];
    leastSquaresTerms(texels, estimate16, median, terms);
    ASSERT_EQ(leastSquaresPredictFactored(weights, weight_sum, texels, estimate16, median),
              leastSquaresPredict(weights, median, terms))
        << "round " << round;
  }
}

TEST(PtmCodec, ExplicitTablesCodeCombsSmallerAndRoundTrip) {
  // Texels on multiples of 16: every residual of the median, and most of the parent's, is a
  // multiple of 4 or 16, which no model of the families is shaped for.
  for (uint32_t channels = 1; channels <= 4; ++channels) {
    PyramidTiles comb = makePyramid(128, 128, channels, 64, 0, channels, 16);
    size_t with_tables = 0;
    expectCoarseToFineRoundTrip(
        comb, channels,
        [&](const Image& tile, const ParentTexels* parent) {
          auto payload = encodeTile(Codec::kPtm, tile.view(), {}, parent);
          if (payload) with_tables += hasTables(*payload);
          return payload;
        },
        fmt::format("comb, {} channels", channels));
    EXPECT_EQ(with_tables, 5u) << "every tile of the comb pyramid carries tables";
    // The tables are worth their bytes: against the same walk with the family models alone,
    // as the recording estimates it without them.
    const Image tile = comb.tile(0, 0, 0), parent_tile = comb.tile(1, 0, 0);
    const ParentTexels parent = parentOf(parent_tile, 0, 0, 64, 0);
    PtmRecording recording;
    ASSERT_TRUE(recordPtm(tile.view(), &parent, Predictor::kNeighbourMedian, PtmCoder::kRans,
                          nullptr, nullptr, recording)
                    .has_value());
    std::vector<uint8_t> params;
    const double family_bits =
        rans::chooseModels(rans::FamilyId::kGeometric12, recording.counts, params);
    const std::vector<uint8_t> payload = encodeRecordedPtm(recording, PtmCoder::kRans, nullptr);
    ASSERT_TRUE(hasTables(payload));
    EXPECT_LT(double(payload.size()), 0.9 * family_bits / 8)
        << payload.size() << " bytes against " << family_bits / 8 << " without tables";
    EXPECT_EQ(decodeOrDie(payload, 64, channels, &parent).texels, tile.texels);
  }
}

TEST(PtmCodec, TheDefaultTakesTheFastestCoderWithinThreePercentOfCoderSix) {
  // One channel has nothing to chain: coders 2 and 4 are 1 and 3 in another order, no
  // smaller, so the default never picks them; nor coder 6, whose errors do not save 3 % on
  // this smooth tile. Coder 7 (lanes), the fastest to decode, comes within 3 % of coder 6.
  Image grey = makeLevel0(64, 64, 1, 4);
  auto grey_payload = encodeTile(Codec::kPtm, grey.view(), {}, nullptr);
  ASSERT_TRUE(grey_payload.has_value());
  EXPECT_EQ(coderIn(*grey_payload), PtmCoder::kRansLanes) << int((*grey_payload)[1]);
  EXPECT_EQ(*grey_payload, expectedDefaultPayload(grey, nullptr));
  // Colour channels that err together: chaining saves far more than 3 %.
  const Image colour = makeTileWhoseChannelsErrTogether(23);
  auto colour_payload = encodeTile(Codec::kPtm, colour.view(), {}, nullptr);
  ASSERT_TRUE(colour_payload.has_value());
  EXPECT_TRUE(isChainedCoder(coderIn(*colour_payload))) << int((*colour_payload)[1]);
  EXPECT_EQ(*colour_payload, expectedDefaultPayload(colour, nullptr));
  EXPECT_EQ(decodeOrDie(*colour_payload, 64, 3, nullptr).texels, colour.texels);
  // Slopes beside noise: only the neighbours' errors tell them apart, by more than 3 %. Without
  // a parent, coder 6 weighs them beside the neighbours' gradients.
  const Image slopes = makeTileOfSlopesBesideNoise(31);
  auto slopes_payload = encodeTile(Codec::kPtm, slopes.view(), {}, nullptr);
  ASSERT_TRUE(slopes_payload.has_value());
  EXPECT_EQ(coderIn(*slopes_payload), PtmCoder::kRansParentErrors);
  EXPECT_EQ(*slopes_payload, expectedDefaultPayload(slopes, nullptr));
  EXPECT_EQ(decodeOrDie(*slopes_payload, 64, 3, nullptr).texels, slopes.texels);
}

TEST(PtmCodec, EstimatesMatchTheRansPayloadsToWithinTheirStates) {
  PyramidTiles pyramid = makePyramid(256, 256, 3, 128, 0, 13);
  const Image child = pyramid.tile(0, 1, 1);
  const Image parent_tile = pyramid.tile(1, 0, 0);
  ParentTexels parent = parentOf(parent_tile, 1, 1, 128, 0);
  for (PtmCoder coder : kCoders)
    for (Predictor predictor : kParentPredictors) {
      const auto payload = encodePtm(child.view(), {}, &parent, predictor, coder, nullptr);
      const auto estimate = estimatePtmBytes(child.view(), {}, &parent, predictor, coder, nullptr);
      ASSERT_TRUE(payload.has_value());
      ASSERT_TRUE(estimate.has_value());
      // zstd's estimate is its payload; rANS's is the models' bit count, which the coder meets
      // to within its final states (4 bytes per channel) and a byte of rounding.
      if (coder == PtmCoder::kZstd)
        EXPECT_EQ(*estimate, payload->size()) << int(predictor);
      else
        EXPECT_LE(std::abs(double(*estimate) - double(payload->size())), 4.0 * 3 + 1)
            << int(predictor) << " coder " << int(coder);
    }
}

// The default encoder records a walk once and estimates and encodes every coder that walks
// alike from it: that must give what estimating and encoding each coder on its own gives.
TEST(PtmCodec, ARecordedWalkEstimatesAndEncodesEveryCoderThatWalksAlike) {
  PyramidTiles pyramid = makePyramid(256, 256, 3, 128, 0, 17);
  const Image child = pyramid.tile(0, 0, 1);
  const Image parent_tile = pyramid.tile(1, 0, 0);
  ParentTexels parent = parentOf(parent_tile, 0, 1, 128, 0);
  EXPECT_TRUE(walksAlike(PtmCoder::kRans, PtmCoder::kRansMixture));
  EXPECT_TRUE(walksAlike(PtmCoder::kRans, PtmCoder::kRansLanes));
  EXPECT_TRUE(walksAlike(PtmCoder::kRansChained, PtmCoder::kRansMixtureChained));
  EXPECT_FALSE(walksAlike(PtmCoder::kRans, PtmCoder::kRansChained));
  EXPECT_FALSE(walksAlike(PtmCoder::kRansMixtureChained, PtmCoder::kRansParentErrors));
  const ParentTexels* const parents[] = {&parent, nullptr};  // coded against it, and on its own
  for (const ParentTexels* with : parents)
    for (PtmCoder recorded_for : kCoders) {
      if (!isRansCoder(recorded_for)) continue;
      for (Predictor predictor : kParentPredictors) {
        PtmLeastSquaresFit fit;
        PtmRecording recording;
        ASSERT_TRUE(recordPtm(child.view(), with, predictor, recorded_for, nullptr, &fit, recording)
                        .has_value());
        for (PtmCoder coder : kCoders) {
          if (!isRansCoder(coder) || !walksAlike(recorded_for, coder)) continue;
          const auto estimate = estimatePtmBytes(child.view(), {}, with, predictor, coder, nullptr);
          const auto payload = encodePtm(child.view(), {}, with, predictor, coder, nullptr);
          ASSERT_TRUE(estimate.has_value() && payload.has_value());
          std::vector<uint8_t> models;
          EXPECT_EQ(estimateRecordedPtm(recording, coder, &models), *estimate)
              << int(predictor) << " coder " << int(coder) << " recorded for " << int(recorded_for);
          EXPECT_EQ(encodeRecordedPtm(recording, coder, nullptr), *payload)
              << int(predictor) << " coder " << int(coder) << " recorded for " << int(recorded_for);
          // The models the estimate chose make the same payload.
          EXPECT_EQ(encodeRecordedPtm(recording, coder, nullptr, &models), *payload)
              << int(predictor) << " coder " << int(coder);
        }
      }
    }
  PtmRecording unused;
  EXPECT_FALSE(recordPtm(child.view(), &parent, Predictor::kParentNearest, PtmCoder::kZstd, nullptr,
                         nullptr, unused)
                   .has_value());
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

}  // namespace
}  // namespace tessera::detail
