// The scene section (docs/format.md, "Scenes"): golden bytes written by hand from the spec's
// tables, round trips, the scene directory found in the section table, every
// prefix of a node head rejected, and the node table's tree rules.
#include "format/scene.h"

#include <cstring>

#include <gtest/gtest.h>

#include "format/byte_io.h"
#include "format/checksum.h"
#include "format/directory.h"

namespace tessera::detail {
namespace {

FileHeader sceneHeader() {
  FileHeader header;
  header.version_minor = 1;
  header.file_bytes = 1 << 20;
  header.image_count = 2;
  header.root = {128, 64 * 2, 0x11};
  return header;
}

SceneDirectory goldenDirectory() {
  SceneDirectory d;
  d.node_count = 3;
  d.object_count = 2;
  d.mesh_count = 1;
  d.texture_count = 2;
  d.tree_depth = 2;
  d.max_children = 8;
  d.leaf_capacity = 16;
  d.bounds = {{-1, 0, -2}, {1, 4, 2}};
  d.node_table = {512, 3 * 96, 0xAA};
  d.texture_table = {800, 2 * 64, 0xBB};
  d.coarse = {16384, 100, 0xCC};
  return d;
}

TEST(SceneFormat, DirectoryGoldenBytes) {
  // Bytes by hand from the table in docs/format.md, "Scene directory".
  std::vector<uint8_t> golden(128, 0);
  const uint8_t head[] = {3, 0, 0, 0, 2,  0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0,  // counts
                          2, 0, 8, 0, 16, 0, 0, 0};                         // depth, fan-out, leaf
  std::memcpy(golden.data(), head, sizeof(head));
  const float box[6] = {-1, 0, -2, 1, 4, 2};
  std::memcpy(golden.data() + 24, box, 24);  // little-endian IEEE 754 on this host
  const uint64_t refs[9] = {512, 288, 0xAA, 800, 128, 0xBB, 16384, 100, 0xCC};
  std::memcpy(golden.data() + 48, refs, 72);
  EXPECT_EQ(encodeSceneDirectory(goldenDirectory()), golden);
  Result<SceneDirectory> decoded = decodeSceneDirectory(golden, sceneHeader(), "g.tess");
  ASSERT_TRUE(decoded.has_value()) << decoded.error().message;
  EXPECT_EQ(*decoded, goldenDirectory());
}

TEST(SceneFormat, SceneDirectoryIsTheSectionOfKind1) {
  const BlockRef scene{256, 128, 0x0123456789ABCDEFull};
  const SectionEntry sections[] = {{2, {40000, 96, 0x55}}, {1, scene}};
  Result<BlockRef> ref = decodeSceneRef(sections, "s.tess");
  ASSERT_TRUE(ref.has_value()) << ref.error().message;
  EXPECT_EQ(*ref, scene);
  // No section of kind 1 (or no section table at all): no scene.
  EXPECT_EQ(decodeSceneRef(std::span(sections, 1), "p.tess")->length_bytes, 0u);
  EXPECT_EQ(decodeSceneRef({}, "p.tess")->length_bytes, 0u);
}

TEST(SceneFormat, SceneReferenceOfTheWrongLengthIsRejected) {
  const SectionEntry sections[] = {{1, {256, 100, 1}}};
  auto ref = decodeSceneRef(sections, "s.tess");
  ASSERT_FALSE(ref.has_value());
  EXPECT_NE(ref.error().message.find("scene directory of 100 bytes"), std::string::npos);
}

NodeRecord leaf(uint8_t depth, uint32_t first_object, uint32_t objects, uint64_t offset,
                uint64_t bytes) {
  NodeRecord n;
  n.bounds = {{-1, 0, -2}, {0, 4, 2}};
  n.depth = depth;
  n.first_object = first_object;
  n.object_count = objects;
  n.offset_bytes = offset;
  n.head_bytes = uint32_t(nodeHeadBytes(objects, 0, 0));
  n.own_bytes = bytes;
  n.subtree_bytes = bytes;
  return n;
}

std::vector<NodeRecord> smallTree() {
  NodeRecord root;
  root.bounds = {{-1, 0, -2}, {1, 4, 2}};
  root.subtree_nodes = 3;
  root.child_count = 2;
  root.first_mesh = 0;
  root.mesh_count = 1;
  root.texture_count = 2;
  root.offset_bytes = 16384;
  root.head_bytes = uint32_t(nodeHeadBytes(0, 1, 2));
  root.own_bytes = 1000;
  root.subtree_bytes = 1000 + 400 + 300;
  NodeRecord a = leaf(1, 0, 1, 17384, 400), b = leaf(1, 1, 1, 17784, 300);
  a.first_texture = b.first_texture = 2;
  a.first_mesh = b.first_mesh = 1;
  b.bounds = {{0, 0, -2}, {1, 4, 2}};
  return {root, a, b};
}

TEST(SceneFormat, NodeRecordGoldenBytes) {
  NodeRecord n = smallTree()[1];
  n.head_checksum = 0x5566778899AABBCCull;
  std::vector<uint8_t> bytes = encodeNodeRecords({&n, 1});
  ASSERT_EQ(bytes.size(), 96u);
  const float box[6] = {-1, 0, -2, 0, 4, 2};
  EXPECT_EQ(std::memcmp(bytes.data(), box, 24), 0);
  const uint8_t fields[] = {1, 0, 0, 0, 0, 0, 1, 0,   // subtree 1, children 0, depth 1, reserved
                            0, 0, 0, 0, 1, 0, 0, 0,   // first object 0, 1 object
                            2, 0, 0, 0, 0, 0, 0, 0,   // first texture 2, none
                            1, 0, 0, 0, 0, 0, 0, 0};  // first mesh 1, none
  EXPECT_EQ(std::memcmp(bytes.data() + 24, fields, sizeof(fields)), 0);
  EXPECT_EQ(loadU64(bytes.data() + 56), 17384u);
  EXPECT_EQ(loadU32(bytes.data() + 64), 16u + 128u);
  EXPECT_EQ(loadU64(bytes.data() + 72), 0x5566778899AABBCCull);
  EXPECT_EQ(loadU64(bytes.data() + 80), 400u);
  EXPECT_EQ(loadU64(bytes.data() + 88), 400u);
  auto decoded = decodeNodeRecords(bytes, 1, goldenDirectory(), sceneHeader(), "g.tess");
  ASSERT_TRUE(decoded.has_value()) << decoded.error().message;
  EXPECT_EQ((*decoded)[0], n);
}

TEST(SceneFormat, NodeTableRulesHoldForAWellFormedTree) {
  std::vector<NodeRecord> nodes = smallTree();
  auto bytes = encodeNodeRecords(nodes);
  auto decoded = decodeNodeRecords(bytes, 0, goldenDirectory(), sceneHeader(), "g.tess");
  ASSERT_TRUE(decoded.has_value()) << decoded.error().message;
  EXPECT_TRUE(validateNodeTable(*decoded, goldenDirectory(), "g.tess").has_value());
}

TEST(SceneFormat, NodeTableRejectsAGapBetweenSiblingSubtrees) {
  std::vector<NodeRecord> nodes = smallTree();
  nodes[2].offset_bytes += 8;  // a hole: the subtree would not be one range
  auto result = validateNodeTable(nodes, goldenDirectory(), "g.tess");
  ASSERT_FALSE(result.has_value());
  EXPECT_NE(result.error().message.find("contiguous"), std::string::npos) << result.error().message;
}

TEST(SceneFormat, NodeTableRejectsAChildOutsideItsParent) {
  std::vector<NodeRecord> nodes = smallTree();
  nodes[2].bounds.max[0] = 5;
  EXPECT_FALSE(validateNodeTable(nodes, goldenDirectory(), "g.tess").has_value());
}

TEST(SceneFormat, NodeRecordRejectsObjectsOnAnInnerNode) {
  std::vector<NodeRecord> nodes = smallTree();
  nodes[0].object_count = 1;
  nodes[0].head_bytes = uint32_t(nodeHeadBytes(1, 1, 2));
  auto bytes = encodeNodeRecords(nodes);
  auto decoded = decodeNodeRecords(bytes, 0, goldenDirectory(), sceneHeader(), "g.tess");
  ASSERT_FALSE(decoded.has_value());
  EXPECT_NE(decoded.error().message.find("node 0: an inner node holds objects"), std::string::npos);
}

ImageInfo textureInfo() {
  ImageInfo info;
  info.width_px = 200;
  info.height_px = 100;
  info.channels = 3;
  info.tile_size_px = 64;
  info.level_count = levelCountFor(200, 100, 64);
  info.page_tiles_log2 = 3;
  info.default_codec = Codec::kJpeg;
  return info;
}

TEST(SceneFormat, TextureRecordGoldenBytesAndRoundTrip) {
  TextureRecord t;
  t.image = 1;
  t.node = 2;
  t.users = 7;
  t.info = textureInfo();
  t.coarsest.kind = TileKind::kUniform;
  t.coarsest.uniform_rgba = 0x00332211;
  std::vector<uint8_t> bytes = encodeTextureRecords({&t, 1});
  const uint8_t golden[32] = {1,   0, 0, 0, 2,   0, 0, 0, 7, 0, 0, 0, 0, 0, 0, 0,
                              200, 0, 0, 0, 100, 0, 0, 0, 3, 6, 0, 3, 3, 3, 0, 0};
  EXPECT_EQ(std::memcmp(bytes.data(), golden, 32), 0);
  EXPECT_EQ(loadU32(bytes.data() + 32), 0x00332211u);  // uniform colour
  EXPECT_EQ(bytes[32 + 12], 1);                        // kind uniform
  auto decoded = decodeTextureRecords(bytes, 1, goldenDirectory(), sceneHeader(), "g.tess");
  ASSERT_TRUE(decoded.has_value()) << decoded.error().message;
  EXPECT_TRUE((*decoded)[0] == t);
}

NodeHead sampleHead() {
  NodeHead head;
  MeshRecord m;
  m.mesh = 0;
  m.vertex_count = 4;
  m.index_count = 6;
  m.attributes = kMeshUv0;
  m.codec = GeometryCodecId::kMeshopt;
  m.vertex_part_bytes = 30;
  m.blob = {16384 + nodeHeadBytes(0, 1, 2) + 200, 60, 0x77};
  head.meshes.push_back(m);
  for (uint32_t k = 0; k < 2; ++k) {
    NodeTextureRecord t;
    t.texture = k;
    t.info = textureInfo();
    t.pages = {16384 + nodeHeadBytes(0, 1, 2) + 100 * k, texturePagesBytes(t.info), 0x99};
    head.textures.push_back(t);
  }
  return head;
}

TEST(SceneFormat, NodeHeadRoundTripsAndEveryPrefixIsRejected) {
  const NodeRecord root = smallTree()[0];
  const NodeHead head = sampleHead();
  const std::vector<uint8_t> bytes = encodeNodeHead(head);
  ASSERT_EQ(bytes.size(), root.head_bytes);
  auto decoded = decodeNodeHead(bytes, root, 0, goldenDirectory(), sceneHeader(), "g.tess");
  ASSERT_TRUE(decoded.has_value()) << decoded.error().message;
  EXPECT_EQ(decoded->meshes, head.meshes);
  ASSERT_EQ(decoded->textures.size(), 2u);
  EXPECT_EQ(decoded->textures[1].pages, head.textures[1].pages);
  for (size_t n = 0; n < bytes.size(); ++n) {
    std::vector<uint8_t> prefix(bytes.begin(), bytes.begin() + n);  // a fresh allocation
    EXPECT_FALSE(
        decodeNodeHead(prefix, root, 0, goldenDirectory(), sceneHeader(), "g.tess").has_value())
        << n;
  }
}

TEST(SceneFormat, NodeHeadRejectsABlobOutsideItsNode) {
  const NodeRecord root = smallTree()[0];
  NodeHead head = sampleHead();
  head.meshes[0].blob.offset_bytes = root.offset_bytes + root.own_bytes - 10;
  auto decoded =
      decodeNodeHead(encodeNodeHead(head), root, 0, goldenDirectory(), sceneHeader(), "g.tess");
  ASSERT_FALSE(decoded.has_value());
  EXPECT_NE(decoded.error().message.find("node 0 mesh 0 geometry"), std::string::npos)
      << decoded.error().message;
}

TEST(SceneFormat, TransformedBoxHoldsEveryTransformedCorner) {
  SceneBox box{{0, 0, 0}, {1, 2, 3}};
  const std::array<float, 12> m = {0, -1, 0, 10, 1, 0, 0, 20, 0, 0, 2, 30};  // rotate z, scale z
  SceneBox out = transformBox(box, m);
  EXPECT_EQ(out, (SceneBox{{8, 20, 30}, {10, 21, 36}}));
}

}  // namespace
}  // namespace tessera::detail
