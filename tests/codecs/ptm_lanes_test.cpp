// ptm's lane coder (coder 7, ptm_lanes.h): whole pyramids round-trip bit-exactly with both of
// its decoders, the SIMD one (where the processor has AVX-512) and the walk every processor
// runs; it codes coder 1's symbols, so its size follows coder 1's estimate; and it has
// predictor 5 without predictor 4's estimate only. Hostile payloads of coder 7 are in
// codec_ptm_hostile_test.cpp.
#include <algorithm>
#include <cmath>
#include <span>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include "codecs/encode.h"
#include "ptm/ptm_encode.h"
#include "ptm/ptm_lanes.h"
#include "ptm/ptm_walk.h"
#include "ptm_test_fixtures.h"
#include "support/test_images.h"

namespace tessera::detail {
namespace {

using test::nextRandom;

// Where a coder-7 payload's model bytes start: after the header and predictor 5's weights.
size_t modelsAt(std::span<const uint8_t> payload, uint32_t channels) {
  return ptm::kHeaderBytes +
         (payload[0] == uint8_t(Predictor::kLeastSquares) ? lsWeightBytes(channels) : 0);
}

// A coder-7 payload's context models, its explicit tables' included, and where its lane
// section starts: after one model byte per context and the tables.
struct LaneModels {
  std::vector<rans::Model> tables;
  std::vector<const rans::Model*> context_models;
  size_t section_at = 0;
};

LaneModels laneModels(std::span<const uint8_t> payload, uint32_t channels) {
  LaneModels out;
  const bool has_parent = payload[0] != uint8_t(Predictor::kRoot);
  const size_t count = size_t(has_parent ? ptm::kParentContexts : ptm::kRootContexts) * channels;
  const size_t models_at = modelsAt(payload, channels);
  const rans::Model* family = rans::models(ptm::lanes::kFamily);
  for (size_t i = 0; i < count; ++i) out.context_models.push_back(&family[payload[models_at + i]]);
  out.section_at = models_at + count;
  if ((payload[1] & kPtmTablesFlag) != 0) {
    const size_t section =
        rans::readTables(payload.subspan(out.section_at), uint32_t(count),
                         rans::scaleBits(ptm::lanes::kFamily), out.tables, out.context_models);
    EXPECT_NE(section, 0u) << "the payload's tables";
    out.section_at += section;
  }
  return out;
}

// The payload's escaped residuals, all channels: from the lane section's stream lengths.
uint32_t escapeBytes(std::span<const uint8_t> payload, uint32_t channels) {
  const size_t lengths =
      laneModels(payload, channels).section_at + size_t(channels) * ptm::lanes::kLanes * 4;
  uint32_t total = 0;
  for (uint32_t c = 0; c < channels; ++c) {
    const uint8_t* escape_length = payload.data() + lengths + c * 8 + 4;
    total += uint32_t(escape_length[0]) | uint32_t(escape_length[1]) << 8 |
             uint32_t(escape_length[2]) << 16 | uint32_t(escape_length[3]) << 24;
  }
  return total;
}

// Decodes a coder-7 payload by `path`: the walk in the lanes' order, as decodePtm would where
// AVX-512 is missing, or the fastest. The SIMD decoder gets a walk without predictor 4's planes,
// as decodePtm gives it; the walk one with them, and it must refuse one without.
Image decodeWithLanes(std::span<const uint8_t> payload, uint32_t side, uint32_t channels,
                      const ParentTexels* parent, ptm::lanes::Path path) {
  Image out(side, side, channels);
  const Predictor predictor = Predictor(payload[0]);
  const bool has_parent = predictor != Predictor::kRoot;
  PtmState state;
  ptm::AxisMap columns, rows;
  const auto* weights = reinterpret_cast<const int8_t*>(payload.data() + ptm::kHeaderBytes);
  const bool planes = path == ptm::lanes::Path::kScalar || !ptm::lanes::simdAvailable();
  auto walk =
      ptm::prepareWalk(out.texels.data(), side, side, channels, has_parent ? parent : nullptr,
                       predictor, PtmCoder::kRansLanes, weights, state, columns, rows, planes);
  EXPECT_TRUE(walk.has_value());
  if (!walk) return out;
  // Predictor 4's estimate for predictor 4 only: coder 7's predictor 5 has none.
  const bool estimates = predictor == Predictor::kParentCorrected;
  EXPECT_EQ(walk->estimates, estimates);
  EXPECT_EQ(walk->upsampled != nullptr, estimates && planes);
  const LaneModels models = laneModels(payload, channels);
  const bool green_led = (payload[1] & kPtmGreenLedFlag) != 0;
  std::vector<uint8_t> padded;
  if (estimates && path == ptm::lanes::Path::kScalar) {
    Image scratch_out(side, side, channels);
    PtmState other;
    ptm::AxisMap other_columns, other_rows;
    auto without =
        ptm::prepareWalk(scratch_out.texels.data(), side, side, channels, parent, predictor,
                         PtmCoder::kRansLanes, weights, other, other_columns, other_rows, false);
    EXPECT_TRUE(without.has_value());
    if (without) {
      EXPECT_FALSE(ptm::lanes::decode(payload.subspan(models.section_at), *without, channels,
                                      predictor, models.context_models, green_led, padded, path))
          << "the walk without predictor 4's planes";
    }
  }
  EXPECT_TRUE(ptm::lanes::decode(payload.subspan(models.section_at), *walk, channels, predictor,
                                 models.context_models, green_led, padded, path));
  return out;
}

// The round trip checked the fastest decoder; the walk must give the same texels.
void expectEveryDecoderAgrees(std::span<const uint8_t> payload, uint32_t side, uint32_t channels,
                              const ParentTexels* parent, const Image& tile) {
  EXPECT_EQ(decodeWithLanes(payload, side, channels, parent, ptm::lanes::Path::kScalar).texels,
            tile.texels)
      << "the walk";
  EXPECT_EQ(decodeWithLanes(payload, side, channels, parent, ptm::lanes::Path::kFastest).texels,
            tile.texels)
      << "the fastest decoder";
}

TEST(PtmLanes, PyramidsRoundTripBitExactlyWithEveryDecoder) {
  // Odd sizes and borders put blocks across tile edges and bands of fewer than eight rows at
  // the bottom; a noisy source makes residuals that only an escape can carry.
  // Predictor 4's pull and its division by 12 are exercised hardest by a source of extremes:
  // the noisy case flips bits 0-6 of every texel, the extreme one sets texels to 0 or 255.
  struct Case {
    uint32_t width, height, border, tile_px;
    bool noisy;
    bool extreme = false;
  };
  if (!ptm::lanes::simdAvailable())
    GTEST_LOG_(INFO) << "no AVX-512 here: the fastest path is the walk";
  for (const Case& c : {Case{133, 77, 0, 32, false}, Case{97, 130, 1, 32, false},
                        Case{71, 69, 2, 32, false}, Case{101, 99, 3, 32, true},
                        Case{300, 270, 1, 128, true}, Case{67, 45, 1, 32, true, true}}) {
    for (uint32_t channels = 1; channels <= 4; ++channels) {
      PyramidTiles pyramid =
          makePyramid(c.width, c.height, channels, c.tile_px, c.border, channels + 3);
      if (c.noisy) {
        uint32_t seed = channels;
        for (uint8_t& texel : pyramid.levels[0].texels)
          texel = c.extreme ? uint8_t((nextRandom(seed) & 1) != 0 ? 255 : 0)
                            : uint8_t(texel ^ (nextRandom(seed) & 0x7f));
        // Keep the levels a floor-average pyramid of the noisy base.
        for (size_t l = 1; l < pyramid.levels.size(); ++l)
          pyramid.levels[l] = floorDownsample(pyramid.levels[l - 1]);
      }
      const uint32_t side = c.tile_px + 2 * c.border;
      for (Predictor predictor : {Predictor::kParentNearest, Predictor::kNeighbourMedian,
                                  Predictor::kParentCorrected, Predictor::kLeastSquares}) {
        uint32_t escapes = 0;
        expectCoarseToFineRoundTrip(
            pyramid, channels,
            [&](const Image& tile, const ParentTexels* parent) {
              auto payload =
                  encodePtm(tile.view(), {}, parent, predictor, PtmCoder::kRansLanes, nullptr);
              if (payload) {
                EXPECT_EQ(coderIn(*payload), PtmCoder::kRansLanes);
                EXPECT_FALSE(isGreenLed(*payload));
                EXPECT_EQ((*payload)[0], uint8_t(parent ? predictor : Predictor::kRoot));
                expectEveryDecoderAgrees(*payload, side, channels, parent, tile);
                escapes += escapeBytes(*payload, channels);
              }
              // Green-led contexts (3 and 4 channels): the same symbols, red's and blue's
              // contexts after green's residual; the fastest decoder by decodeTile.
              if (payload && channels >= 3) {
                PtmRecording recording;
                EXPECT_TRUE(recordPtm(tile.view(), parent, predictor, PtmCoder::kRansLanes, nullptr,
                                      nullptr, recording)
                                .has_value());
                const std::vector<uint8_t> led = greenLedLanesPayload(recording);
                EXPECT_TRUE(isGreenLed(led));
                EXPECT_EQ(coderIn(led), PtmCoder::kRansLanes);
                EXPECT_EQ(decodeOrDie(led, side, channels, parent).texels, tile.texels);
                expectEveryDecoderAgrees(led, side, channels, parent, tile);
              }
              return payload;
            },
            fmt::format("{}x{} border {} channels {} predictor {}", c.width, c.height, c.border,
                        channels, int(predictor)));
        if (c.noisy) {
          EXPECT_GT(escapes, 0u) << "the noisy case must exercise escapes";
        }
      }
    }
  }
}

TEST(PtmLanes, LeastSquaresRoundTripsWithAnyWeights) {
  // Predictor 5's weights are any bytes a payload holds but the estimate's, which coder 7 does
  // not have: the extremes (-128 and 127) and random ones push every term of its sum to its
  // bounds, on a source of 0s and 255s; and the fit without the estimate, from an encoder that
  // walked with it.
  if (!ptm::lanes::simdAvailable())
    GTEST_LOG_(INFO) << "no AVX-512 here: the fastest path is the walk";
  for (uint32_t channels = 1; channels <= 4; ++channels) {
    PyramidTiles pyramid = makePyramid(75, 69, channels, 32, 1, channels + 11);
    uint32_t seed = 7 * channels;
    for (uint8_t& texel : pyramid.levels[0].texels) texel = (nextRandom(seed) & 1) != 0 ? 255 : 0;
    for (size_t l = 1; l < pyramid.levels.size(); ++l)
      pyramid.levels[l] = floorDownsample(pyramid.levels[l - 1]);
    const uint32_t side = 32 + 2;
    enum Kind { kLowest, kHighest, kRandom, kFitted };
    for (const Kind kind : {kLowest, kHighest, kRandom, kFitted}) {
      PtmLeastSquaresFit fit;
      fit.fitted = kind != kFitted;
      for (int8_t& weight : fit.weights)
        weight = kind == kLowest    ? int8_t(-128)
                 : kind == kHighest ? int8_t(127)
                                    : int8_t(nextRandom(seed));
      for (size_t i = 0; i < std::size(fit.weights); ++i)
        fit.weights_without_estimate[i] = i % kLsTerms == kLsTerms - 1 ? 0 : fit.weights[i];
      expectCoarseToFineRoundTrip(
          pyramid, channels,
          [&](const Image& tile, const ParentTexels* parent) {
            const bool fitted = fit.fitted;
            auto payload = encodePtm(tile.view(), {}, parent, Predictor::kLeastSquares,
                                     PtmCoder::kRansLanes, nullptr, &fit);
            // Each tile fits its own weights.
            if (kind == kFitted) fit.fitted = fitted;
            if (payload && parent != nullptr) {
              EXPECT_EQ((*payload)[0], uint8_t(Predictor::kLeastSquares));
              const auto* weights =
                  reinterpret_cast<const int8_t*>(payload->data() + ptm::kHeaderBytes);
              EXPECT_FALSE(usesEstimate(weights, channels));
              expectEveryDecoderAgrees(*payload, side, channels, parent, tile);
            }
            return payload;
          },
          fmt::format("channels {} weights {}", channels, int(kind)));
    }
  }
}

TEST(PtmLanes, ExplicitTablesRoundTripWithEveryDecoderAndPayForThemselves) {
  // Texels on multiples of 16 (a comb): residuals that no model of the family is shaped for.
  // The SIMD decoders build the tables behind their thread's copy of the family's symbol table;
  // the scalar lanes use the tables' models. The tiles are small, so the payloads take a table
  // wherever one saves any bytes (lanesPayloadWithAnyTables), not only where the encoder would.
  for (uint32_t channels = 1; channels <= 4; ++channels) {
    const PyramidTiles comb = makePyramid(75, 69, channels, 32, 1, channels + 5, 16);
    const uint32_t side = 32 + 2;
    for (Predictor predictor : {Predictor::kParentNearest, Predictor::kNeighbourMedian,
                                Predictor::kParentCorrected, Predictor::kLeastSquares}) {
      size_t with_tables = 0, led_with_tables = 0, bytes = 0, bytes_without = 0;
      expectCoarseToFineRoundTrip(
          comb, channels,
          [&](const Image& tile, const ParentTexels* parent) -> Result<std::vector<uint8_t>> {
            PtmRecording recording;
            TESSERA_TRY(recordPtm(tile.view(), parent, predictor, PtmCoder::kRansLanes, nullptr,
                                  nullptr, recording));
            std::vector<uint8_t> payload = lanesPayloadWithAnyTables(recording);
            // With green-led contexts, whose decoders read green's frequency of zero from
            // the tables too.
            if (channels >= 3) {
              const std::vector<uint8_t> led = greenLedLanesPayload(recording, true);
              if (hasTables(led)) {
                ++led_with_tables;
                EXPECT_EQ(decodeOrDie(led, side, channels, parent).texels, tile.texels);
                expectEveryDecoderAgrees(led, side, channels, parent, tile);
              }
            }
            if (hasTables(payload)) {
              ++with_tables;
              expectEveryDecoderAgrees(payload, side, channels, parent, tile);
              // The same symbols under the family's models alone.
              std::vector<uint8_t> params;
              const double bits = rans::chooseModels(ptm::lanes::kFamily, recording.counts, params);
              bytes += payload.size();
              bytes_without += recording.header.size() + params.size() + size_t(bits / 8) +
                               ptm::lanes::headerBytes(channels);
            }
            return payload;
          },
          fmt::format("comb, channels {} predictor {}", channels, int(predictor)));
      EXPECT_GT(with_tables, 0u) << channels << " channels, predictor " << int(predictor);
      if (channels >= 3) {
        EXPECT_GT(led_with_tables, 0u) << channels << " channels, predictor " << int(predictor);
      }
      EXPECT_LT(bytes, bytes_without) << channels << " channels, predictor " << int(predictor);
    }
  }
}

TEST(PtmLanes, TheEncoderSendsOnlyTablesWorthTheirDecoding) {
  // Each table costs the SIMD decoder a build of kScale slot entries, so coder 7 takes one only
  // where it saves kTableMinGainBytes. Random texels of two levels, 0 and 31, leave the median
  // residuals of 0 and +-31, which every model of the family spreads over the codes between:
  // on a 32-px tile no table saves that much, on a 128-px tile some do.
  auto tableCount = [](const LaneModels& models) { return models.tables.size(); };
  for (const uint32_t tile_px : {32u, 128u}) {
    PyramidTiles pyramid = makePyramid(2 * tile_px, 2 * tile_px, 3, tile_px, 0, 9);
    uint32_t seed = tile_px;
    for (uint8_t& texel : pyramid.levels[0].texels) texel = (nextRandom(seed) & 1) != 0 ? 31 : 0;
    for (size_t l = 1; l < pyramid.levels.size(); ++l)
      pyramid.levels[l] = floorDownsample(pyramid.levels[l - 1]);
    const Image child = pyramid.tile(0, 1, 1), parent_tile = pyramid.tile(1, 0, 0);
    const ParentTexels parent = parentOf(parent_tile, 1, 1, tile_px, 0);
    PtmRecording recording;
    ASSERT_TRUE(recordPtm(child.view(), &parent, Predictor::kNeighbourMedian, PtmCoder::kRans,
                          nullptr, nullptr, recording)
                    .has_value());
    const std::vector<uint8_t> any = lanesPayloadWithAnyTables(recording);
    const std::vector<uint8_t> sent = encodeRecordedPtm(recording, PtmCoder::kRansLanes, nullptr);
    const size_t any_tables = tableCount(laneModels(any, 3));
    const size_t sent_tables = tableCount(laneModels(sent, 3));
    EXPECT_GT(any_tables, 0u) << tile_px;
    if (tile_px == 32) {
      EXPECT_EQ(sent_tables, 0u);
    } else {
      EXPECT_GT(sent_tables, 0u);
      EXPECT_LT(sent_tables, any_tables);
    }
    EXPECT_EQ(decodeOrDie(sent, tile_px, 3, &parent).texels, child.texels) << tile_px;
  }
}

TEST(PtmLanes, CodesCoderOnesSymbolsToWithinItsStates) {
  PyramidTiles pyramid = makePyramid(256, 256, 3, 128, 0, 13);
  const Image child = pyramid.tile(0, 1, 1);
  const Image parent_tile = pyramid.tile(1, 0, 0);
  ParentTexels parent = parentOf(parent_tile, 1, 1, 128, 0);
  const ParentTexels* const parents[] = {&parent, nullptr};  // coded against it, and alone
  for (const ParentTexels* with : parents)
    for (Predictor predictor : {Predictor::kParentNearest, Predictor::kNeighbourMedian,
                                Predictor::kParentCorrected, Predictor::kLeastSquares}) {
      const auto lanes =
          encodePtm(child.view(), {}, with, predictor, PtmCoder::kRansLanes, nullptr);
      const auto estimate =
          estimatePtmBytes(child.view(), {}, with, predictor, PtmCoder::kRansLanes, nullptr);
      ASSERT_TRUE(lanes.has_value() && estimate.has_value());
      // The estimate is coder 1's model bits plus the lane section's header; the states the
      // header holds carry up to two bytes each of what the symbols' bits counted.
      const double states = 3.0 * ptm::lanes::kLanes;
      EXPECT_LE(std::abs(double(*estimate) - double(lanes->size())), 2 * states + 3 * 2 + 1);
      // A walk recorded for coder 1, with the weights coder 7 takes, encodes coder 7 as
      // encodePtm does.
      PtmLeastSquaresFit fit;
      fit.without_estimate = true;
      PtmRecording recording;
      ASSERT_TRUE(
          recordPtm(child.view(), with, predictor, PtmCoder::kRans, nullptr, &fit, recording)
              .has_value());
      EXPECT_TRUE(walksAlike(PtmCoder::kRans, PtmCoder::kRansLanes));
      EXPECT_EQ(encodeRecordedPtm(recording, PtmCoder::kRansLanes, nullptr), *lanes);
    }
}

TEST(PtmLanes, ToggledFlagsAndTheEstimatesWeightAreRefused) {
  PyramidTiles pyramid = makePyramid(128, 128, 3, 64, 0, 5);
  const Image child = pyramid.tile(0, 1, 0);
  const Image parent_tile = pyramid.tile(1, 0, 0);
  ParentTexels parent = parentOf(parent_tile, 1, 0, 64, 0);
  auto payload = encodePtm(child.view(), {}, &parent, Predictor::kNeighbourMedian,
                           PtmCoder::kRansLanes, nullptr);
  ASSERT_TRUE(payload.has_value());
  Image out(64, 64, 3);
  // The tables flag toggled (the section read where there is none, or skipped where there is
  // one) is corrupt; the green-led flag toggled reads red's and blue's symbols under other
  // models, so the streams do not end where the symbols do.
  for (const uint8_t flag : {kPtmTablesFlag, kPtmGreenLedFlag}) {
    std::vector<uint8_t> bad = *payload;
    bad[1] = uint8_t(bad[1] ^ flag);
    EXPECT_FALSE(decodeTile(Codec::kPtm, bad, out, &parent).has_value()) << int(flag);
  }
  ASSERT_TRUE(decodeTile(Codec::kPtm, *payload, out, &parent).has_value());
  EXPECT_EQ(out.texels, child.texels);
  // Predictor 5 with coder 7 takes the weights without predictor 4's estimate, whatever the fit
  // asks for; a payload that gives the estimate a weight is refused by name.
  PtmLeastSquaresFit fit;
  auto least_squares = encodePtm(child.view(), {}, &parent, Predictor::kLeastSquares,
                                 PtmCoder::kRansLanes, nullptr, &fit);
  ASSERT_TRUE(least_squares.has_value());
  EXPECT_FALSE(usesEstimate(reinterpret_cast<const int8_t*>(least_squares->data() + 2), 3));
  EXPECT_EQ(decodeOrDie(*least_squares, 64, 3, &parent).texels, child.texels);
  std::vector<uint8_t> bad = *least_squares;
  bad[ptm::kHeaderBytes + kLsTerms - 1] = 1;
  auto refused = decodeTile(Codec::kPtm, bad, out, &parent);
  ASSERT_FALSE(refused.has_value());
  EXPECT_EQ(refused.error().code, ErrorCode::kUnsupported);
  EXPECT_NE(refused.error().message.find("coder 7"), std::string::npos);
  EXPECT_NE(refused.error().message.find("removed"), std::string::npos);
}

TEST(PtmLanes, GreenLeadsRedAndBlueInCodedTexelsOnly) {
  // Four channels: a coded texel of position 1, class 5, with green's residual zero, then the
  // same with green's residual 3 (a byte of 3), then a coded texel of class 7 after a nonzero
  // green, then a remainder (all four channels' contexts kCodedContexts + class).
  using ptm::kActivityClasses;
  using ptm::kCodedContexts;
  const uint8_t symbols[] = {4, 0, 250, 1, 9, 3, 0, 0, 1, 255, 0, 7, 1, 1, 1, 1};
  const uint8_t p1 = kActivityClasses;  // position 1's first context
  std::vector<uint8_t> contexts = {uint8_t(p1 + 5),
                                   uint8_t(p1 + 5),
                                   uint8_t(p1 + 5),
                                   uint8_t(p1 + 5),
                                   uint8_t(p1 + 5),
                                   uint8_t(p1 + 5),
                                   uint8_t(p1 + 5),
                                   uint8_t(p1 + 5),
                                   7,
                                   7,
                                   7,
                                   7,
                                   uint8_t(kCodedContexts + 2),
                                   uint8_t(kCodedContexts + 2),
                                   uint8_t(kCodedContexts + 2),
                                   uint8_t(kCodedContexts + 2)};
  const std::vector<uint8_t> before = contexts;
  ptm::lanes::leadByGreen(symbols, contexts, 4);
  // Halved after a zero green, raised by two (at most to the last class) after any other.
  const std::vector<uint8_t> expected = {uint8_t(p1 + 2),
                                         uint8_t(p1 + 5),
                                         uint8_t(p1 + 2),
                                         uint8_t(p1 + 5),
                                         uint8_t(p1 + 7),
                                         uint8_t(p1 + 5),
                                         uint8_t(p1 + 7),
                                         uint8_t(p1 + 5),
                                         7,
                                         7,
                                         7,
                                         7,
                                         before[12],
                                         before[13],
                                         before[14],
                                         before[15]};
  EXPECT_EQ(contexts, expected);
  EXPECT_EQ(ptm::greenLedClass(0, true), 0u);
  EXPECT_EQ(ptm::greenLedClass(6, false), kActivityClasses - 1);
}

TEST(PtmLanes, GreenLedContextsCodeColourThatErrsTogetherSmaller) {
  // Colour that errs together (makeColourThatErrsTogether): the lead saves at least 5 % with
  // the median, whose residuals are zero in the texels without noise, and 2 % with the nearest
  // parent, whose prediction, the block's mean, takes in its noisy texels.
  const PyramidTiles pyramid = makeColourThatErrsTogether(17);
  const Image child = pyramid.tile(0, 1, 1), parent_tile = pyramid.tile(1, 0, 0);
  const ParentTexels parent = parentOf(parent_tile, 1, 1, 128, 0);
  for (const auto& [predictor, percent] :
       {std::pair{Predictor::kNeighbourMedian, 5u}, std::pair{Predictor::kParentNearest, 2u}}) {
    PtmRecording recording;
    ASSERT_TRUE(recordPtm(child.view(), &parent, predictor, PtmCoder::kRansLanes, nullptr, nullptr,
                          recording)
                    .has_value());
    const std::vector<uint8_t> plain = encodeRecordedPtm(recording, PtmCoder::kRansLanes, nullptr);
    PtmRecording led;
    leadRecordingByGreen(recording, led);
    const std::vector<uint8_t> led_payload = encodeRecordedPtm(led, PtmCoder::kRansLanes, nullptr);
    EXPECT_LT(led_payload.size() * 100, plain.size() * (100 - percent)) << int(predictor);
    // The estimate follows the payload, as for coder 7 without the lead.
    EXPECT_LE(std::abs(double(estimateRecordedPtm(led, PtmCoder::kRansLanes)) -
                       double(led_payload.size())),
              2.0 * 3 * ptm::lanes::kLanes + 3 * 2 + 1);
    EXPECT_EQ(decodeOrDie(led_payload, 128, 3, &parent).texels, child.texels);
    expectEveryDecoderAgrees(led_payload, 128, 3, &parent, child);
  }
}

}  // namespace
}  // namespace tessera::detail
