// The section table (docs/format.md, "Section table"): golden bytes written by hand from the
// spec's table, the header reference read by the 1.0 header decoder, every prefix rejected,
// duplicate kinds rejected, unknown kinds skipped, and an archive's first bytes holding both a
// scene and a procedural section decoded back to both directories.
#include "format/sections.h"

#include <cstring>

#include <gtest/gtest.h>

#include "format/byte_io.h"
#include "format/checksum.h"
#include "format/procedural.h"
#include "format/scene.h"

namespace tessera::detail {
namespace {

FileHeader testHeader() {
  FileHeader header;
  header.version_minor = 1;
  header.file_bytes = 1 << 20;
  header.image_count = 1;
  header.root = {128, 64, 0x11};
  return header;
}

std::vector<SectionEntry> bothSections() {
  return {{uint32_t(SectionKind::kScene), {256, 128, 0xAA}},
          {uint32_t(SectionKind::kProcedural), {384, 160, 0xBB}}};
}

TEST(SectionTable, GoldenBytes) {
  // Bytes by hand from docs/format.md, "Section table": kind u32, reserved u32, offset, length
  // and checksum u64, little-endian.
  const uint8_t golden[64] = {
      1,    0, 0, 0, 0, 0, 0, 0,  // kind 1 (scene), reserved
      0,    1, 0, 0, 0, 0, 0, 0,  // offset 256
      0x80, 0, 0, 0, 0, 0, 0, 0,  // length 128
      0xAA, 0, 0, 0, 0, 0, 0, 0,  // checksum
      2,    0, 0, 0, 0, 0, 0, 0,  // kind 2 (procedural), reserved
      0x80, 1, 0, 0, 0, 0, 0, 0,  // offset 384
      0xA0, 0, 0, 0, 0, 0, 0, 0,  // length 160
      0xBB, 0, 0, 0, 0, 0, 0, 0,  // checksum
  };
  const std::vector<uint8_t> bytes = encodeSectionTable(bothSections());
  ASSERT_EQ(bytes.size(), sizeof(golden));
  EXPECT_EQ(0, std::memcmp(bytes.data(), golden, sizeof(golden)));
  auto decoded = decodeSectionTable(bytes, testHeader(), "t.tess");
  ASSERT_TRUE(decoded) << decoded.error().message;
  EXPECT_EQ(*decoded, bothSections());
  EXPECT_EQ(findSection(*decoded, SectionKind::kScene), (BlockRef{256, 128, 0xAA}));
  EXPECT_EQ(findSection(*decoded, SectionKind::kProcedural), (BlockRef{384, 160, 0xBB}));
}

TEST(SectionTable, HeaderReferenceIsReadByThe10HeaderDecoder) {
  std::vector<uint8_t> bytes = encodeHeader(testHeader());
  stampSectionTableRef(bytes, {4096, 64, 0x0123456789ABCDEFull});
  // Bytes 8..11: version 1.1; 80..103: the table's reference; 120..127 the checksum of 0..119.
  EXPECT_EQ(loadU16(bytes.data() + 10), 1);
  EXPECT_EQ(loadU64(bytes.data() + 80), 4096u);
  EXPECT_EQ(loadU64(bytes.data() + 88), 64u);
  EXPECT_EQ(loadU64(bytes.data() + 96), 0x0123456789ABCDEFull);
  EXPECT_EQ(loadU64(bytes.data() + 120), checksum64({bytes.data(), 120}));
  auto header = decodeHeader(bytes, "t.tess");
  ASSERT_TRUE(header) << header.error().message;
  auto table = decodeSectionTableRef(bytes, *header, "t.tess");
  ASSERT_TRUE(table) << table.error().message;
  EXPECT_EQ(*table, (BlockRef{4096, 64, 0x0123456789ABCDEFull}));
  // A 1.0 header has no section table, whatever bytes 80..103 hold.
  FileHeader v10 = *header;
  v10.version_minor = 0;
  EXPECT_EQ(decodeSectionTableRef(bytes, v10, "t.tess")->length_bytes, 0u);
  // Bytes 104..119 stay reserved in 1.1.
  std::vector<uint8_t> reserved = bytes;
  reserved[110] = 1;
  EXPECT_FALSE(decodeSectionTableRef(reserved, *header, "t.tess"));
}

TEST(SectionTable, HeaderReferenceRejectsBadBlocks) {
  const FileHeader header = testHeader();
  auto ref = [&](BlockRef table) {
    std::vector<uint8_t> bytes = encodeHeader(header);
    stampSectionTableRef(bytes, table);
    return decodeSectionTableRef(bytes, header, "t.tess");
  };
  EXPECT_TRUE(ref({}));
  EXPECT_FALSE(ref({4096, 0, 7}));                     // empty with a checksum
  EXPECT_FALSE(ref({64, 32, 7}));                      // inside the header
  EXPECT_FALSE(ref({header.file_bytes - 16, 32, 7}));  // past the end
  EXPECT_FALSE(ref({4096, 33, 7}));                    // not whole entries
  EXPECT_FALSE(ref({4096, 65 * 32, 7}));               // over kMaxSections
}

TEST(SectionTable, DecodeRejectsEveryPrefixAndHostileEntries) {
  const std::vector<uint8_t> bytes = encodeSectionTable(bothSections());
  for (size_t n = 0; n < bytes.size(); ++n) {
    if (n == kSectionEntryBytes) continue;  // one whole entry is a valid table
    std::vector<uint8_t> prefix(bytes.begin(), bytes.begin() + n);
    EXPECT_FALSE(decodeSectionTable(prefix, testHeader(), "t.tess")) << n;
  }
  auto with = [&](size_t offset, uint8_t value) {
    std::vector<uint8_t> copy = bytes;
    copy[offset] = value;
    return decodeSectionTable(copy, testHeader(), "t.tess");
  };
  EXPECT_FALSE(with(0, 0));         // kind 0
  EXPECT_FALSE(with(5, 1));         // reserved
  EXPECT_FALSE(with(16, 0));        // length 0
  EXPECT_FALSE(with(8 + 6, 0x10));  // offset past the file
  auto duplicate = with(32, 1);     // two scenes
  ASSERT_FALSE(duplicate);
  EXPECT_NE(duplicate.error().message.find("kind 1 appears twice"), std::string::npos);
}

TEST(SectionTable, UnknownKindsAreKeptAndSkipped) {
  std::vector<SectionEntry> entries = {{77, {2048, 10, 0}},
                                       {uint32_t(SectionKind::kProcedural), {384, 160, 0xBB}}};
  auto decoded = decodeSectionTable(encodeSectionTable(entries), testHeader(), "t.tess");
  ASSERT_TRUE(decoded) << decoded.error().message;
  EXPECT_EQ(*decoded, entries);  // re-encodes to the same bytes
  EXPECT_EQ(findSection(*decoded, SectionKind::kScene).length_bytes, 0u);
  EXPECT_EQ(findSection(*decoded, SectionKind::kProcedural), (BlockRef{384, 160, 0xBB}));
  EXPECT_EQ(decodeSceneRef(*decoded, "t.tess")->length_bytes, 0u);
}

TEST(SectionTable, SceneAndProceduralSectionsRoundTripInOneArchive) {
  SceneDirectory scene;
  scene.node_count = 1;
  scene.tree_depth = 1;
  scene.max_children = 8;
  scene.leaf_capacity = 16;
  scene.node_table = {16384, 96, 0xAA};
  ProceduralDirectory procedural;
  procedural.images = {{{20000, 1000, 5}, 16, 8, 4, Codec::kZstd}};
  procedural.brushes = {{0, 1, BlendMode::kNormal, MaskSource::kNone, 0, 255}};

  // Header, section table, scene directory and procedural directory, as a writer places them.
  std::vector<uint8_t> file(16384, 0);
  const std::vector<uint8_t> scene_bytes = encodeSceneDirectory(scene);
  const std::vector<uint8_t> procedural_bytes = encodeProceduralDirectory(procedural);
  std::memcpy(file.data() + 256, scene_bytes.data(), scene_bytes.size());
  std::memcpy(file.data() + 512, procedural_bytes.data(), procedural_bytes.size());
  const std::vector<SectionEntry> entries = {
      {uint32_t(SectionKind::kProcedural),
       {512, procedural_bytes.size(), checksum64(procedural_bytes)}},
      {uint32_t(SectionKind::kScene), {256, scene_bytes.size(), checksum64(scene_bytes)}}};
  const std::vector<uint8_t> table_bytes = encodeSectionTable(entries);
  std::memcpy(file.data() + 128, table_bytes.data(), table_bytes.size());
  const std::vector<uint8_t> header_bytes = encodeHeader(testHeader());
  std::memcpy(file.data(), header_bytes.data(), header_bytes.size());
  stampSectionTableRef(file, {128, table_bytes.size(), checksum64(table_bytes)});

  // A reader's path: header, table reference, table, each kind it knows.
  auto header = decodeHeader(file, "both.tess");
  ASSERT_TRUE(header) << header.error().message;
  auto table = decodeSectionTableRef(file, *header, "both.tess");
  ASSERT_TRUE(table) << table.error().message;
  const std::span<const uint8_t> table_span(file.data() + table->offset_bytes, table->length_bytes);
  ASSERT_EQ(checksum64(table_span), table->checksum);
  auto sections = decodeSectionTable(table_span, *header, "both.tess");
  ASSERT_TRUE(sections) << sections.error().message;
  auto scene_ref = decodeSceneRef(*sections, "both.tess");
  auto procedural_ref = decodeProceduralRef(*sections, "both.tess");
  ASSERT_TRUE(scene_ref && procedural_ref);
  auto scene_again = decodeSceneDirectory(
      {file.data() + scene_ref->offset_bytes, scene_ref->length_bytes}, *header, "both.tess");
  ASSERT_TRUE(scene_again) << scene_again.error().message;
  EXPECT_EQ(*scene_again, scene);
  auto procedural_again = decodeProceduralDirectory(
      {file.data() + procedural_ref->offset_bytes, procedural_ref->length_bytes}, *header,
      header->image_count, "both.tess");
  ASSERT_TRUE(procedural_again) << procedural_again.error().message;
  EXPECT_EQ(*procedural_again, procedural);
}

}  // namespace
}  // namespace tessera::detail
