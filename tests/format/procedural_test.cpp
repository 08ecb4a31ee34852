// The procedural extension of format 1.1: golden bytes written by hand from docs/format.md
// ("Procedural tiles"), round trips, truncation at every length and hostile fields.
#include "format/procedural.h"

#include <cmath>
#include <cstring>
#include <limits>

#include <gtest/gtest.h>

#include "format/directory.h"

namespace tessera::detail {
namespace {

FileHeader testHeader() {
  FileHeader header;
  header.version_minor = 1;
  header.file_bytes = 1 << 20;
  header.image_count = 1;
  return header;
}

BrushInstance goldenInstance() {
  BrushInstance instance;
  instance.x_px = 1.5;
  instance.y_px = -2.0;
  instance.radius_px = 8.0f;
  instance.rotation_rad = 0.0f;
  instance.scale = 1.0f;
  instance.tint_rgba = 0x80FF4020u;
  instance.brush = 3;
  instance.opacity = 200;
  instance.variant = 1;
  return instance;
}

TEST(ProceduralFormat, InstancePageGoldenBytes) {
  BrushInstance instance = goldenInstance();
  const TileClip clip{2, 3, 256, 258};
  std::vector<uint8_t> bytes = encodeInstancePage({&instance, 1}, {&clip, 1});
  const std::vector<uint8_t> golden = {
      'T',  'I',  'P',  'G',  0x01, 0x00, 0x00, 0x00,  // magic, count 1
      0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xF8, 0x3F,  // x 1.5
      0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xC0,  // y -2.0
      0x00, 0x00, 0x00, 0x41,                          // radius 8.0f
      0x00, 0x00, 0x00, 0x00,                          // rotation 0
      0x00, 0x00, 0x80, 0x3F,                          // scale 1.0f
      0x20, 0x40, 0xFF, 0x80,                          // tint r g b a
      0x03, 0x00, 0x00, 0x00,                          // brush 3
      0xC8, 0x01, 0x00, 0x00,                          // opacity 200, variant 1, reserved
      0x02, 0x00, 0x03, 0x00, 0x00, 0x01, 0x02, 0x01,  // clip [2, 256) x [3, 258)
  };
  EXPECT_EQ(bytes, golden);
  std::vector<TileClip> clips;
  auto decoded = decodeInstancePage(bytes, 4, "t.tess: tile (0,0,0)", &clips);
  ASSERT_TRUE(decoded) << decoded.error().message;
  ASSERT_EQ(clips.size(), 1u);
  EXPECT_EQ(clips[0], clip);
  ASSERT_EQ(decoded->size(), 1u);
  EXPECT_EQ((*decoded)[0].x_px, 1.5);
  EXPECT_EQ((*decoded)[0].tint_rgba, 0x80FF4020u);
  EXPECT_EQ((*decoded)[0].brush, 3u);
  EXPECT_EQ((*decoded)[0].variant, 1);
}

TEST(ProceduralFormat, InstancePageRejectsEveryTruncationAndTrailingByte) {
  std::vector<BrushInstance> instances(3, goldenInstance());
  std::vector<uint8_t> bytes = encodeInstancePage(instances);
  for (size_t n = 0; n < bytes.size(); ++n) {
    std::vector<uint8_t> prefix(bytes.begin(), bytes.begin() + n);
    EXPECT_FALSE(decodeInstancePage(prefix, 4, "p")) << n;
  }
  bytes.push_back(0);
  EXPECT_FALSE(decodeInstancePage(bytes, 4, "p"));
}

TEST(ProceduralFormat, InstancePageRejectsHostileFields) {
  BrushInstance instance = goldenInstance();
  auto edited = [&](auto edit) {
    BrushInstance copy = instance;
    edit(copy);
    return decodeInstancePage(encodeInstancePage({&copy, 1}), 4, "page");
  };
  EXPECT_FALSE(edited([](BrushInstance& i) { i.brush = 4; }));
  EXPECT_FALSE(edited([](BrushInstance& i) { i.radius_px = 0; }));
  EXPECT_FALSE(edited([](BrushInstance& i) { i.scale = -1; }));
  EXPECT_FALSE(edited([](BrushInstance& i) { i.x_px = std::numeric_limits<double>::quiet_NaN(); }));
  EXPECT_FALSE(edited([](BrushInstance& i) { i.rotation_rad = INFINITY; }));
  std::vector<uint8_t> bytes = encodeInstancePage({&instance, 1});
  bytes[8 + 38] = 1;  // reserved
  auto result = decodeInstancePage(bytes, 4, "x.tess: tile (2,1,1)");
  ASSERT_FALSE(result);
  EXPECT_NE(result.error().message.find("x.tess: tile (2,1,1)"), std::string::npos);
  std::vector<uint8_t> huge = encodeInstancePage({});
  huge[4] = 0xFF, huge[5] = 0xFF, huge[6] = 0xFF, huge[7] = 0xFF;  // count 2^32 - 1
  EXPECT_FALSE(decodeInstancePage(huge, 4, "page"));
  const TileClip inverted{5, 0, 4, 10};
  EXPECT_FALSE(decodeInstancePage(encodeInstancePage({&instance, 1}, {&inverted, 1}), 4, "page"));
}

ProceduralDirectory goldenDirectory() {
  ProceduralDirectory directory;
  directory.image = 0;
  directory.height_layer = {{20000, 300, 7}, 64, 32, 1, Codec::kZstd};
  directory.images = {{{16384, 1000, 5}, 16, 8, 4, Codec::kZstd},
                      {{17384, 2000, 6}, 32, 32, 4, Codec::kPng}};
  directory.brushes = {{0, 2, BlendMode::kOverlay, MaskSource::kSlope, 10, 200}};
  return directory;
}

TEST(ProceduralFormat, DirectoryGoldenBytes) {
  std::vector<uint8_t> bytes = encodeProceduralDirectory(goldenDirectory());
  ASSERT_EQ(bytes.size(), 64u + 2 * 40 + 16);
  const uint8_t fixed[24] = {'T', 'P', 'R', 'C', 1, 0, 0, 0,  // magic, version 1, reserved
                             0,   0,   0,   0,                // image 0
                             1,   0,   0,   0,                // 1 brush
                             2,   0,   0,   0,                // 2 images
                             0,   0,   0,   0};
  EXPECT_EQ(0, std::memcmp(bytes.data(), fixed, 24));
  const uint8_t layer[40] = {0x20, 0x4E, 0, 0, 0,  0, 0, 0,   // offset 20000
                             0x2C, 0x01, 0, 0, 0,  0, 0, 0,   // length 300
                             7,    0,    0, 0, 0,  0, 0, 0,   // checksum
                             64,   0,    0, 0, 32, 0, 0, 0,   // 64 x 32
                             1,    1,    0, 0, 0,  0, 0, 0};  // 1 channel, zstd
  EXPECT_EQ(0, std::memcmp(bytes.data() + 24, layer, 40));
  const uint8_t brush[16] = {0, 0, 0, 0, 2, 0, 3, 2, 10, 200, 0, 0, 0, 0, 0, 0};
  EXPECT_EQ(0, std::memcmp(bytes.data() + 64 + 80, brush, 16));
  auto decoded = decodeProceduralDirectory(bytes, testHeader(), 1, "d");
  ASSERT_TRUE(decoded) << decoded.error().message;
  EXPECT_EQ(*decoded, goldenDirectory());
}

TEST(ProceduralFormat, DirectoryRejectsTruncationAndHostileFields) {
  std::vector<uint8_t> bytes = encodeProceduralDirectory(goldenDirectory());
  for (size_t n = 0; n < bytes.size(); ++n)
    EXPECT_FALSE(decodeProceduralDirectory({bytes.data(), n}, testHeader(), 1, "d")) << n;
  auto with = [&](size_t offset, uint8_t value) {
    std::vector<uint8_t> copy = bytes;
    copy[offset] = value;
    return decodeProceduralDirectory(copy, testHeader(), 1, "d");
  };
  EXPECT_FALSE(with(8, 1));             // image 1 of 1
  EXPECT_FALSE(with(64 + 33, 3));       // JPEG is not lossless
  EXPECT_FALSE(with(64 + 32, 3));       // a brush image of 3 channels
  EXPECT_FALSE(with(64 + 80 + 4, 3));   // brush images past the table
  EXPECT_FALSE(with(64 + 80 + 6, 4));   // unknown blend mode
  EXPECT_FALSE(with(64 + 80 + 7, 3));   // unknown mask source
  EXPECT_FALSE(with(64 + 80 + 12, 1));  // reserved
  EXPECT_FALSE(with(64 + 7, 0x40));     // image offset beyond the file
  EXPECT_FALSE(with(64 + 8 + 6, 1));    // huge payload length
  // A masked brush needs the layer.
  ProceduralDirectory no_layer = goldenDirectory();
  no_layer.height_layer = {};
  EXPECT_FALSE(
      decodeProceduralDirectory(encodeProceduralDirectory(no_layer), testHeader(), 1, "d"));
  no_layer.brushes[0].mask = MaskSource::kNone;
  EXPECT_TRUE(decodeProceduralDirectory(encodeProceduralDirectory(no_layer), testHeader(), 1, "d"));
}

TEST(ProceduralFormat, ProceduralDirectoryIsTheSectionOfKind2) {
  const SectionEntry sections[] = {
      {1, {256, 128, 0x11}}, {2, {40000, 96, 0x55}}, {99, {512, 8, 0}}};
  auto block = decodeProceduralRef(sections, "h.tess");
  ASSERT_TRUE(block) << block.error().message;
  EXPECT_EQ(*block, (BlockRef{40000, 96, 0x55}));
  // No section of kind 2: no procedural directory.
  auto none = decodeProceduralRef(std::span(sections, 1), "h.tess");
  ASSERT_TRUE(none);
  EXPECT_EQ(none->length_bytes, 0u);
  // Bounded like the metadata before anything reads it.
  const SectionEntry huge[] = {{2, {40000, kMaxMetadataBytes + 1ull, 0}}};
  auto too_large = decodeProceduralRef(huge, "h.tess");
  ASSERT_FALSE(too_large);
  EXPECT_EQ(too_large.error().code, ErrorCode::kTooLarge);
}

TEST(ProceduralFormat, ProceduralEntriesAreReadIn11AndRejectedIn10) {
  ImageInfo info;
  info.width_px = info.height_px = 1024;
  info.channels = 4;
  info.tile_size_px = 256;
  info.level_count = 3;
  std::vector<TileEntry> entries = {proceduralEntry(20000, 56, 0x1234)};
  TileEntry uniform;
  uniform.kind = TileKind::kUniform;
  uniform.uniform_rgba = 0x11223344;
  entries.push_back(uniform);
  std::vector<uint8_t> bytes = encodeTileEntries(entries);
  EXPECT_EQ(bytes[12], 3);  // kind procedural
  FileHeader header = testHeader();
  auto decoded = decodeTileEntriesProcedural(bytes, info, header, "p");
  ASSERT_TRUE(decoded) << decoded.error().message;
  EXPECT_EQ((*decoded)[0].kind, TileKind::kProcedural);
  EXPECT_EQ((*decoded)[0].offset_bytes, 20000u);
  EXPECT_EQ((*decoded)[0].length_bytes, 56u);
  EXPECT_EQ((*decoded)[1].uniform_rgba, 0x11223344u);
  header.version_minor = 0;
  auto old = decodeTileEntriesProcedural(bytes, info, header, "p");
  ASSERT_FALSE(old);
  EXPECT_EQ(old.error().code, ErrorCode::kUnsupported);
  header.version_minor = 1;
  for (TileEntry bad : {proceduralEntry(20000, 55, 1), proceduralEntry(100, 56, 1),
                        proceduralEntry((1 << 20) - 8, 56, 1)}) {
    EXPECT_FALSE(decodeTileEntriesProcedural(encodeTileEntries({&bad, 1}), info, header, "p"));
  }
  std::vector<uint8_t> with_codec = encodeTileEntries({entries.data(), 1});
  with_codec[13] = 1;
  EXPECT_FALSE(decodeTileEntriesProcedural(with_codec, info, header, "p"));
}

}  // namespace
}  // namespace tessera::detail
