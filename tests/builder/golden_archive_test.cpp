// Golden archives: one fixed input per codec (and per option that changes bytes: border,
// chroma, sRGB averaging, payload order, page size, texture sets) must build to exactly the
// bytes it built to before the module restructuring. The expected hashes are the XXH3-64 of
// the archives that Tessera 1750ecb's `tessera build INPUT -o OUT OPTIONS --threads 1` wrote
// (the CLI and buildArchive share their defaults); a change to any byte of the format, a
// codec's payload or the metadata fails here, naming the case. texture_set's hash is newer: the
// synthetic source's ragged no-data edge at a row's last, partial cell was fixed after 1750ecb;
// so are bc1's and bc7's, codecs added after it.
#include <tessera/build.h>

#include <cstdlib>
#include <filesystem>

#include <gtest/gtest.h>
#include <xxhash.h>

#include "support/test_images.h"

namespace tessera {
namespace {

struct GoldenCase {
  const char* name;
  std::vector<std::string> inputs;
  BuildOptions options;  ///< inputs and output are filled in by the test
  uint64_t xxh3;         ///< of the whole archive
  uint64_t bytes;
};

BuildOptions options(Codec codec, uint32_t tile_size_px = 64) {
  BuildOptions o;
  o.codec = codec;
  o.tile_size_px = tile_size_px;
  o.threads = 1;
  return o;
}

std::vector<GoldenCase> goldenCases() {
  std::vector<GoldenCase> cases;
  auto add = [&](const char* name, std::vector<std::string> inputs, BuildOptions o, uint64_t xxh3,
                 uint64_t bytes) {
    cases.push_back({name, std::move(inputs), o, xxh3, bytes});
  };
  BuildOptions o = options(Codec::kRaw);
  add("raw", {"gray.png"}, o, 0x47293ad54ce04c87, 135864);
  o = options(Codec::kZstd);
  o.order = TileOrder::kQuadtree;
  add("zstd", {"graya.png"}, o, 0x4dacbb5e560c13b6, 145069);
  o = options(Codec::kLz4);
  o.order = TileOrder::kRowMajor;
  o.page_tiles_log2 = 3;
  add("lz4", {"synthetic:700x500:7:3"}, o, 0xff651c4c5b03b2fb, 905147);
  add("jpeg", {"synthetic:700x500:7:4"}, options(Codec::kJpeg), 0x0213f01207a329d7, 196796);
  o = options(Codec::kJpeg);
  o.quality = 60;
  o.border_px = 1;
  add("jpeg_gray", {"gray.png"}, o, 0x8a831b476661a6b5, 68394);
  o = options(Codec::kJpeg, 128);
  o.chroma_subsampling = false;
  o.quality = 70;
  o.border_px = 2;
  o.srgb_downsample = true;
  add("jpeg444", {"synthetic:700x500:9:3"}, o, 0x50f94776b7dbea88, 121993);
  o = options(Codec::kPng);
  o.border_px = 1;
  add("png", {"synthetic:700x500:7:4"}, o, 0x87fb590433abe333, 728176);
  o = options(Codec::kWebp);
  o.effort = 3;
  add("webp", {"graya.png"}, o, 0x2bfc969859bb8d4f, 52500);
  add("ptm", {"synthetic:700x500:7:3"}, options(Codec::kPtm), 0xb73a6d8848daf78b, 393461);
  o = options(Codec::kPtm);
  o.effort = 1;
  o.border_px = 1;
  add("ptm_effort1", {"gray.png"}, o, 0xca9fab2b868c4f70, 61005);
  o = options(Codec::kPtm);
  o.effort = 2;
  add("ptm_effort2", {"synthetic:700x500:7:4"}, o, 0x186337eb239c86c9, 442504);
  // bc1's bytes are libsquish's (Debian 1.15); bc7's are Tessera's own encoder's. Hashes from
  // the build that introduced them (branch bc-codecs).
  o = options(Codec::kBc1);
  o.border_px = 1;
  add("bc1", {"synthetic:300x200:5:3"}, o, 0xa608142b793106f4, 77192);
  o = options(Codec::kBc7);
  o.border_px = 1;
  add("bc7", {"graya.png"}, o, 0x62b81b854a1ef67f, 151176);
  o = options(Codec::kZstd);
  o.image_names = {"a", "b"};
  add("texture_set", {"synthetic:300x200:1:3", "graya.png"}, o, 0x649dadc90df19380, 220333);
  return cases;
}

// The PNG inputs: a smooth field with detail in gray, and a radial alpha ramp. The archive
// depends on their pixels and file names only, not on how the PNG was compressed.
void writeGoldenInputs() {
  const uint32_t width = 300, height = 200;
  std::vector<uint8_t> gray(size_t(width) * height), gray_alpha(size_t(width) * height * 2);
  for (uint32_t y = 0; y < height; ++y)
    for (uint32_t x = 0; x < width; ++x) {
      const uint8_t value = uint8_t((x * 3 + y * 5 + (x * y) / 7) & 255);
      const int dx = int(x) - 150, dy = int(y) - 100;
      const uint8_t alpha = uint8_t(std::min(255, (dx * dx + dy * dy) / 40));
      gray[size_t(y) * width + x] = value;
      gray_alpha[(size_t(y) * width + x) * 2] = value;
      gray_alpha[(size_t(y) * width + x) * 2 + 1] = alpha;
    }
  ASSERT_EQ(test::writePng(
                "gray.png",
                {.width_px = width, .height_px = height, .colour = test::PngColour::kGray}, gray),
            "");
  ASSERT_EQ(test::writePng(
                "graya.png",
                {.width_px = width, .height_px = height, .colour = test::PngColour::kGrayAlpha},
                gray_alpha),
            "");
}

TEST(GoldenArchive, EveryCodecBuildsTheSameBytesAsBefore) {
  // Sources are named relative to the working directory, as the metadata records them.
  const std::filesystem::path previous = std::filesystem::current_path();
  std::filesystem::current_path(test::testTempDir());
  writeGoldenInputs();
  for (const GoldenCase& golden : goldenCases()) {
    BuildOptions o = golden.options;
    o.inputs = golden.inputs;
    o.output = std::string(golden.name) + ".tess";
    Result<BuildReport> built = buildArchive(o);
    ASSERT_TRUE(built) << golden.name << ": " << built.error().message;
    const std::vector<uint8_t> bytes = test::readFileBytes(o.output);
    EXPECT_EQ(bytes.size(), golden.bytes) << golden.name;
    EXPECT_EQ(XXH3_64bits(bytes.data(), bytes.size()), golden.xxh3)
        << golden.name << ": the archive's bytes changed";
  }
  std::filesystem::current_path(previous);
}

}  // namespace
}  // namespace tessera
