// The rANS coder under ptm's coders 1-4 and 6 (ptm_rans.h): every model of both families is a
// proper distribution whose bucket tables find every slot, the mixture family pays off on residuals
// drawn from two spreads, and payloads written with family 1 before family 2 existed still
// decode and encode byte for byte.
#include <algorithm>
#include <cmath>
#include <span>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "codecs/encode.h"
#include "ptm/ptm_encode.h"
#include "ptm/ptm_rans.h"
#include "support/test_images.h"

namespace tessera::detail {
namespace {

using test::nextRandom;

template <uint32_t kScaleBits>
void expectProperFamily(rans::FamilyId id) {
  constexpr uint32_t kScale = 1u << kScaleBits;
  const rans::Model* models = rans::models(id);
  for (uint32_t k = 0; k < rans::kModelCount; ++k) {
    uint32_t sum = 0;
    for (uint32_t s = 0; s < rans::kAlphabet; ++s) {
      ASSERT_GE(models[k].freq[s], 1u) << "model " << k << " symbol " << s;
      EXPECT_EQ(models[k].start[s], sum);
      EXPECT_EQ(models[k].entry[s], sum | uint32_t(models[k].freq[s]) << 16);
      // The decoder's bucket search finds the symbol of every slot.
      for (uint32_t i = 0; i < models[k].freq[s]; ++i)
        ASSERT_EQ(models[k].template symbolOf<kScaleBits>(sum + i), s)
            << "model " << k << " slot " << sum + i;
      sum += models[k].freq[s];
    }
    EXPECT_EQ(sum, kScale) << "model " << k;
  }
  // Each kind runs from near-certain zero to spread-out residuals.
  EXPECT_GT(models[0].freq[0], kScale * 9 / 10);
  EXPECT_LT(models[rans::kModelCount - 1].freq[0], kScale / 20);
}

TEST(PtmRans, EveryModelIsAProperDistributionAndZigzagIsABijection) {
  expectProperFamily<rans::scaleBits(rans::FamilyId::kGeometric12)>(rans::FamilyId::kGeometric12);
  expectProperFamily<rans::scaleBits(rans::FamilyId::kMixture15)>(rans::FamilyId::kMixture15);
  for (uint32_t v = 0; v < 256; ++v) {
    EXPECT_LT(rans::zigzag(uint8_t(v)), 256u);
    EXPECT_EQ(rans::unzigzag(rans::zigzag(uint8_t(v))), uint8_t(v));
  }
  EXPECT_EQ(rans::zigzag(0), 0u);
  EXPECT_EQ(rans::zigzag(uint8_t(-1)), 1u);
  EXPECT_EQ(rans::zigzag(1), 2u);
}

// A 12x10 RGB tile coded without a parent by coders 1 and 2 before model family 2 and the
// decoder's bucket tables existed: family 1's payloads must decode, and encode, unchanged.
Image makeGoldenTile() {
  Image tile(12, 10, 3);
  for (uint32_t y = 0; y < 10; ++y)
    for (uint32_t x = 0; x < 12; ++x)
      for (uint32_t c = 0; c < 3; ++c)
        tile.row(y)[size_t(x) * 3 + c] =
            uint8_t(40 + 9 * x + 5 * y + 30 * c + ((x * y + c) % 7) * 3);
  return tile;
}
constexpr uint8_t kGoldenCoder1[] = {
    0x00, 0x01, 0x80, 0x00, 0x00, 0x80, 0x80, 0xc1, 0xb0, 0xf5, 0xf3, 0x00, 0x00, 0xeb, 0xeb, 0xee,
    0xf1, 0xec, 0x80, 0x00, 0x00, 0x80, 0x80, 0xb1, 0x06, 0xab, 0xff, 0x5f, 0x9c, 0x02, 0x26, 0xaf,
    0x20, 0x5a, 0xff, 0xff, 0x5d, 0x07, 0xb4, 0x10, 0x49, 0x72, 0xa4, 0x25, 0x78, 0x7e, 0x5a, 0x8c,
    0x62, 0x9c, 0x82, 0x65, 0x11, 0x32, 0xb5, 0xb8, 0xe0, 0xf3, 0xd8, 0x66, 0xff, 0x97, 0x12, 0x68,
    0x4f, 0xcd, 0x5c, 0xdd, 0x66, 0x68, 0x3a, 0x00, 0x00, 0xcf, 0x77, 0xc8, 0xf9, 0x67, 0x75, 0x1f,
    0xd6, 0x4e, 0x2d, 0xd0, 0x34, 0xd1, 0x9d, 0xce, 0xb0, 0x68, 0x8c, 0x69, 0x5b, 0x95, 0x8b, 0xd7,
    0x4c, 0xcc, 0xf1, 0x6e, 0x65, 0xcb, 0xa2, 0x0f, 0x01, 0x57, 0xd2, 0x9c, 0x11, 0x38, 0x40, 0x58,
    0x7b, 0x04, 0xfc, 0xb3, 0x15, 0xf2, 0xf9, 0xcf, 0x87, 0xaf, 0x57, 0x57, 0x64, 0x02, 0xde, 0xff,
    0x35, 0x14, 0xd4, 0x53, 0xe9, 0x61, 0x3b, 0x95, 0xd4, 0x93, 0xe8, 0xfe, 0x55, 0xe0, 0x43, 0x32,
    0x00, 0xa8, 0xe9, 0x95, 0x68, 0xd4, 0xea, 0xa2, 0x89, 0x06, 0xb6, 0xf2, 0xe6, 0xe3, 0xb2, 0xa9,
    0xaa, 0xb7, 0x2b, 0x3d, 0xfd, 0xba, 0x73, 0xd7, 0x0a, 0x13, 0xe3, 0xcf, 0xd9, 0x98, 0x78, 0xeb,
    0x11, 0x3c, 0x75, 0x00, 0x38, 0xd2, 0x20, 0x78, 0x5a, 0xb0, 0xd3, 0x91, 0x92, 0x25, 0xec, 0xed,
    0x3c, 0x6f, 0x0a, 0x6b, 0xd3, 0x9b, 0x4c, 0xd5, 0xde, 0x59, 0xda, 0xd0, 0x21, 0xe5, 0xdf, 0xd8,
    0x5c, 0xcd, 0x18, 0x21, 0x95, 0x77, 0xd7, 0xa9, 0xd8, 0x67, 0x6f, 0x15, 0x53, 0x0f, 0x87, 0xff,
    0xf9, 0x5a, 0x35, 0xd6, 0xe5, 0x4b, 0x1d, 0x58, 0x81, 0x48, 0xa3, 0x96,
};
constexpr uint8_t kGoldenCoder2[] = {
    0x00, 0x02, 0xf3, 0x00, 0x00, 0xeb, 0xeb, 0xee, 0xf1, 0xec, 0x00, 0x00, 0x00, 0x80, 0x00, 0x80,
    0x80, 0xaf, 0x80, 0x80, 0x80, 0xaf, 0x00, 0x00, 0x3c, 0xb1, 0x26, 0xaf, 0x20, 0x5a, 0xff, 0x6f,
    0xa9, 0x00, 0xda, 0x0f, 0x79, 0x22, 0x72, 0x44, 0x1a, 0x5b, 0x27, 0xad, 0x7e, 0x5a, 0x8c, 0x62,
    0x9c, 0x82, 0x65, 0x11, 0x32, 0xb5, 0x8f, 0xe0, 0x4a, 0xf3, 0x51, 0x1f, 0xff, 0xf0, 0x19, 0x8e,
    0x4f, 0xcd, 0xdd, 0xa7, 0x32, 0x68, 0x3a, 0xa8, 0xcf, 0xd3, 0xc9, 0x77, 0x71, 0x5e, 0x75, 0x11,
    0xa7, 0x4e, 0x13, 0x33, 0x34, 0x58, 0x7f, 0x9d, 0xd9, 0x8c, 0xe0, 0x69, 0x73, 0x98, 0x8b, 0x07,
    0x81, 0x4c, 0xb0, 0x04, 0xf1, 0x30, 0x89, 0x70, 0xa2, 0x8b, 0xd2, 0x98, 0x11, 0x6f, 0x38, 0x99,
    0xf7, 0x58, 0xb3, 0x32, 0xb3, 0x15, 0xf7, 0x9d, 0xea, 0x1e, 0x57, 0xb6, 0x73, 0xd0, 0x57, 0xde,
    0xb3, 0x81, 0x35, 0x29, 0xf2, 0xd4, 0x1b, 0x3b, 0xe9, 0xea, 0x4c, 0x85, 0x93, 0x50, 0xb7, 0xe0,
    0x9a, 0x00, 0x4a, 0x95, 0xa8, 0xc5, 0xea, 0x68, 0xcc, 0x8d, 0xa2, 0x59, 0x5c, 0x42, 0xf2, 0xb2,
    0xda, 0xa4, 0x2b, 0xc2, 0x3f, 0xe4, 0x90, 0xd7, 0xef, 0xa4, 0x1a, 0x0a, 0x13, 0xd8, 0xce, 0xeb,
    0x05, 0xe4, 0x3c, 0x40, 0x7b, 0x38, 0xeb, 0x44, 0x78, 0xc1, 0x33, 0xb0, 0x77, 0x18, 0x25, 0xec,
    0x43, 0x6f, 0xd9, 0x39, 0x6b, 0xe0, 0x44, 0xde, 0x59, 0xda, 0x95, 0xfd, 0xd0, 0xe5, 0x54, 0xac,
    0x1e, 0xcd, 0xf9, 0x95, 0x0c, 0x9c, 0xd7, 0xd8, 0x9f, 0x67, 0x6f, 0xcf, 0xcb, 0x53, 0xe7, 0x77,
    0x87, 0x79, 0x5e, 0x35, 0xf5, 0xd0, 0x4b, 0x8b, 0xc1, 0x48, 0x59, 0x96, 0xb2, 0xb9,
};

TEST(PtmCodec, PayloadsOfModelFamilyOneDecodeAndEncodeAsWrittenBefore) {
  const Image tile = makeGoldenTile();
  for (auto [coder, golden] :
       {std::pair{PtmCoder::kRans, std::span<const uint8_t>(kGoldenCoder1)},
        std::pair{PtmCoder::kRansChained, std::span<const uint8_t>(kGoldenCoder2)}}) {
    Image out(12, 10, 3);
    ASSERT_TRUE(decodeTile(Codec::kPtm, golden, out, nullptr).has_value()) << int(coder);
    EXPECT_EQ(out.texels, tile.texels) << int(coder);
    auto payload = encodePtm(tile.view(), {}, nullptr, Predictor::kRoot, coder, nullptr);
    ASSERT_TRUE(payload.has_value());
    EXPECT_TRUE(std::equal(payload->begin(), payload->end(), golden.begin(), golden.end()))
        << int(coder);
  }
}

// Residuals of one context drawn from two Laplacians, a quiet one most of the time and a busy
// one otherwise, as where a context's activity class holds flat and textured texels alike.
std::vector<uint8_t> mixedResiduals(size_t count, uint32_t seed) {
  std::vector<uint8_t> residuals(count);
  uint32_t random = seed;
  for (uint8_t& r : residuals) {
    const double scale = nextRandom(random) % 10 < 7 ? 0.6 : 8.0;
    const double u = (nextRandom(random) % 1000000 + 0.5) / 1e6;
    const int size = int(-scale * std::log(u));
    r = uint8_t(nextRandom(random) % 2 ? size : -size);
  }
  return residuals;
}

TEST(PtmRans, TheMixtureFamilyCodesMixedResidualsInFewerBits) {
  const std::vector<uint8_t> residuals = mixedResiduals(20000, 5);
  const std::vector<uint8_t> contexts(residuals.size(), 0);
  const rans::ContextCounts counts = rans::countByContext(residuals, contexts, 1, 1);
  std::vector<uint8_t> params;
  const double geometric = rans::chooseModels(rans::FamilyId::kGeometric12, counts, params);
  const double mixture = rans::chooseModels(rans::FamilyId::kMixture15, counts, params);
  EXPECT_LT(mixture, geometric * 0.97) << mixture << " bits against " << geometric;
  // And the coder meets the model's count.
  std::vector<uint8_t> work, out;
  const rans::Model* model = &rans::models(rans::FamilyId::kMixture15)[params[0]];
  rans::encode(rans::FamilyId::kMixture15, residuals, contexts, 1, 1, std::span(&model, 1), work,
               out);
  EXPECT_LE(std::abs(double(out.size()) - mixture / 8), 5.0);
}

TEST(PtmRans, SharedModelsAreFewerAndCostAtMostTheirSlack) {
  // 40 contexts of Laplacian residuals with scales close to one another and counts from 20 to
  // 20,000: the small contexts' best models sit near the large ones', so sharing finds them;
  // but context kLoner's scale is far from every other's, and it keeps its own model.
  std::vector<uint8_t> residuals, contexts;
  uint32_t random = 17;
  constexpr uint32_t kContexts = 40, kLoner = 37;
  for (uint32_t context = 0; context < kContexts; ++context) {
    const double scale = context == kLoner ? 12.0 : 1.0 + 0.1 * (context % 10);
    const uint32_t symbols = context % 4 == 0 ? 20000 : 20 + 40 * context;
    for (uint32_t i = 0; i < symbols; ++i) {
      const double u = (nextRandom(random) % 1000000 + 0.5) / 1e6;
      const int size = int(-scale * std::log(u));
      residuals.push_back(uint8_t(nextRandom(random) % 2 ? size : -size));
      contexts.push_back(uint8_t(context));
    }
  }
  const rans::ContextCounts counts = rans::countByContext(residuals, contexts, 1, kContexts);
  const auto family = rans::FamilyId::kGeometric12;
  std::vector<uint8_t> best;
  rans::chooseModels(family, counts, best);
  constexpr double kSlack = 0.03;
  std::vector<uint8_t> shared = best;
  const double shared_bits = rans::shareModels(family, counts, kSlack, shared);
  auto distinct = [](std::vector<uint8_t> models) {
    std::sort(models.begin(), models.end());
    return size_t(std::unique(models.begin(), models.end()) - models.begin());
  };
  EXPECT_LT(distinct(shared), distinct(best));
  const rans::Model* models = rans::models(family);
  double total = 0;
  for (uint32_t context = 0; context < kContexts; ++context) {
    double own = 0, now = 0;
    for (uint32_t symbol = 0; symbol < rans::kAlphabet; ++symbol) {
      const uint32_t n = counts.counts[context * rans::kAlphabet + symbol];
      own += n * double(models[best[context]].cost_bits[symbol]);
      now += n * double(models[shared[context]].cost_bits[symbol]);
    }
    EXPECT_LE(now, own * (1 + kSlack) + 8) << "context " << context;
    total += now;
    // A context moves only onto a model another context keeps.
    if (shared[context] != best[context]) {
      EXPECT_GT(std::count(shared.begin(), shared.end(), shared[context]), 1) << context;
    }
  }
  EXPECT_NEAR(shared_bits, total, 1e-6 * total);
  EXPECT_EQ(shared[kLoner], best[kLoner]);
}

// Residuals on a comb (even magnitudes only, as a palette's steps leave them): no family
// model is shaped so, in context 1; context 0 holds plain geometric residuals a family model
// fits, so it needs no table.
void combAndPlain(size_t count, std::vector<uint8_t>& residuals, std::vector<uint8_t>& contexts) {
  uint32_t random = 9;
  for (size_t i = 0; i < count; ++i) {
    const bool comb = i % 2 == 1;
    const double u = (nextRandom(random) % 1000000 + 0.5) / 1e6;
    int size = int(-3.0 * std::log(u));
    if (comb) size *= 2;
    residuals.push_back(uint8_t(nextRandom(random) % 2 ? size : -size));
    contexts.push_back(uint8_t(comb));
  }
}

TEST(PtmRans, ATableCodesWhatNoFamilyModelFitsAndDecodesExactly) {
  std::vector<uint8_t> residuals, contexts;
  combAndPlain(40000, residuals, contexts);
  const rans::ContextCounts counts = rans::countByContext(residuals, contexts, 1, 2);
  for (const rans::FamilyId family : {rans::FamilyId::kGeometric12, rans::FamilyId::kMixture15}) {
    std::vector<uint8_t> params;
    const double family_bits = rans::chooseModels(family, counts, params);
    rans::Tables tables;
    ASSERT_TRUE(rans::chooseTables(family, counts, params, tables, 0));
    ASSERT_EQ(tables.models.size(), 1u);  // the comb's context only
    EXPECT_EQ(tables.section[0], 0b10);
    EXPECT_LT(tables.bits + 8.0 * double(tables.section.size()), family_bits * 0.9)
        << tables.bits << " bits and a " << tables.section.size() << "-byte table against "
        << family_bits;
    std::vector<uint8_t> work, stream;
    rans::encode(family, residuals, contexts, 1, 2, tables.context_models, work, stream);
    EXPECT_LE(std::abs(double(stream.size()) - tables.bits / 8), 5.0);

    // The decoder's models, from the section alone, decode every residual.
    const rans::Model* decoder_models[2] = {&rans::models(family)[params[0]],
                                            &rans::models(family)[params[1]]};
    std::vector<rans::Model> read;
    ASSERT_EQ(rans::readTables(tables.section, 2, rans::scaleBits(family), read, decoder_models),
              tables.section.size());
    ASSERT_EQ(read.size(), 1u);
    for (uint32_t s = 0; s < rans::kAlphabet; ++s)
      EXPECT_EQ(read[0].freq[s], tables.models[0].freq[s]) << "symbol " << s;
    auto decodeAll = [&]<uint32_t kScaleBits>() {
      rans::Decoder<kScaleBits> decoder;
      EXPECT_TRUE(decoder.start(stream, 1));
      for (size_t i = 0; i < residuals.size(); ++i)
        ASSERT_EQ(decoder.decode(0, *decoder_models[contexts[i]]), residuals[i]) << "symbol " << i;
      EXPECT_TRUE(decoder.finishedCleanly(1));
    };
    if (family == rans::FamilyId::kGeometric12)
      decodeAll.template operator()<12>();
    else
      decodeAll.template operator()<15>();
  }
}

TEST(PtmRans, AMalformedTablesSectionIsRefused) {
  std::vector<uint8_t> residuals, contexts;
  combAndPlain(20000, residuals, contexts);
  const rans::ContextCounts counts = rans::countByContext(residuals, contexts, 1, 2);
  std::vector<uint8_t> params;
  rans::chooseModels(rans::FamilyId::kMixture15, counts, params);
  rans::Tables tables;
  ASSERT_TRUE(rans::chooseTables(rans::FamilyId::kMixture15, counts, params, tables, 0));
  const std::vector<uint8_t> good = tables.section;
  auto read = [](std::vector<uint8_t> section) {
    std::vector<rans::Model> models;
    const rans::Model* context_models[2] = {};
    return rans::readTables(section, 2, 15, models, context_models);
  };
  ASSERT_EQ(read(good), good.size());
  for (size_t length = 0; length < good.size(); ++length)  // every truncation
    EXPECT_EQ(read({good.begin(), good.begin() + ptrdiff_t(length)}), 0u) << length;
  std::vector<uint8_t> bad = good;
  bad[0] = 0;  // no table flagged
  EXPECT_EQ(read(bad), 0u);
  bad = good;
  bad[0] |= 0x04;  // a context past the last
  EXPECT_EQ(read(bad), 0u);
  for (uint8_t count : {0, 65, 255}) {
    bad = good;
    bad[1] = count;
    EXPECT_EQ(read(bad), 0u) << int(count);
  }
  // Every level zero: no symbol has a weight.
  bad = good;
  std::fill(bad.begin() + 2, bad.end(), uint8_t(0));
  EXPECT_EQ(read(bad), 0u);
  // A padding bit set (6 bits a level rarely fill the last byte).
  const size_t levels = good[1];
  if (levels * rans::kTableLevelBits % 8 != 0) {
    bad = good;
    bad.back() |= 0x80;
    EXPECT_EQ(read(bad), 0u);
  }
}

}  // namespace
}  // namespace tessera::detail
