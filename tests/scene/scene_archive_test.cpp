// Scene archives end to end: a synthetic scene built with buildScene, read back with
// SceneArchive (counting reads), checked against the format's rules, and opened by the 1.0
// reader as ordinary images.
#include <tessera/scene.h>

#include <map>
#include <set>

#include <gtest/gtest.h>

#include <tessera/archive.h>
#include <tessera/scene_build.h>

#include "format/scene.h"
#include "scene/scene_test_support.h"

namespace tessera {
namespace {

using test::CountingSource;
using test::ScratchDir;

struct BuiltScene {
  std::string path;
  SceneBuildReport report;
};

BuiltScene buildSynthetic(const ScratchDir& dir, const std::string& spec,
                          GeometryCodec geometry = GeometryCodec::kMeshopt,
                          const std::string& name = "city.tess") {
  SceneBuildOptions options;
  options.input = "synthetic-scene:" + spec;
  options.output = dir.file(name);
  options.tile_size_px = 64;
  options.threads = 2;
  options.leaf_capacity = 8;
  options.max_children = 4;
  options.geometry_codec = geometry;
  Result<SceneBuildReport> report = buildScene(options);
  EXPECT_TRUE(report.has_value()) << report.error().message;
  return {options.output, report.has_value() ? *report : SceneBuildReport{}};
}

std::shared_ptr<SceneArchive> openScene(const std::string& path,
                                        std::shared_ptr<CountingSource>* counter = nullptr) {
  auto file = openFileSource(path);
  EXPECT_TRUE(file.has_value());
  auto counting = std::make_shared<CountingSource>(*file);
  if (counter) *counter = counting;
  auto scene = SceneArchive::open(counting);
  EXPECT_TRUE(scene.has_value()) << scene.error().message;
  return scene.has_value() ? *scene : nullptr;
}

TEST(SceneArchive, OpensWithOneReadAndReadsAnyNodeWithTwoMore) {
  ScratchDir dir;
  BuiltScene built = buildSynthetic(dir, "600:60:3");
  std::shared_ptr<CountingSource> counter;
  auto scene = openScene(built.path, &counter);
  ASSERT_TRUE(scene);
  EXPECT_EQ(counter->reads, 1u) << "open reads the first 16 KiB once";
  EXPECT_EQ(scene->summary().objects, 600u);
  EXPECT_EQ(scene->summary().textures, built.report.summary.textures);
  const uint32_t nodes = scene->summary().nodes;
  for (uint32_t i = 0; i < nodes; i += 7) {
    auto fresh = openScene(built.path, &counter);
    const uint64_t before = counter->reads;
    Result<SceneNode> node = fresh->node(i);
    ASSERT_TRUE(node.has_value()) << node.error().message;
    Result<NodeContents> contents = fresh->readNode(*node);
    ASSERT_TRUE(contents.has_value()) << contents.error().message;
    EXPECT_LE(counter->reads - before, 2u) << "node " << i;
    EXPECT_EQ(contents->objects.size(), node->object_count);
    EXPECT_EQ(contents->textures.size(), node->texture_count);
    EXPECT_EQ(contents->meshes.size(), node->mesh_count);
  }
}

TEST(SceneArchive, NodeTableFormsTheTreeAndEveryObjectIsInOneLeaf) {
  ScratchDir dir;
  BuiltScene built = buildSynthetic(dir, "500:50:4");
  auto scene = openScene(built.path);
  ASSERT_TRUE(scene);
  Result<std::vector<SceneNode>> nodes = scene->allNodes();
  ASSERT_TRUE(nodes.has_value()) << nodes.error().message;
  std::vector<int> seen(scene->summary().objects, 0);
  for (const SceneNode& node : *nodes) {
    Result<NodeContents> contents = scene->readNode(node);
    ASSERT_TRUE(contents.has_value()) << contents.error().message;
    for (const SceneObject& object : contents->objects) {
      ++seen[object.index];
      EXPECT_TRUE(node.isLeaf());
      for (int a = 0; a < 3; ++a) {
        EXPECT_GE(object.bounds.min[a], node.bounds.min[a]);
        EXPECT_LE(object.bounds.max[a], node.bounds.max[a]);
      }
      // The mesh's and every texture's holder is this leaf or an ancestor of it.
      const SceneNode& holder = (*nodes)[object.mesh_node];
      EXPECT_TRUE(node.index >= holder.index && node.index < holder.index + holder.subtree_nodes);
      Result<std::vector<SceneTexture>> texture = scene->textures(object.textures[0], 1);
      ASSERT_TRUE(texture.has_value());
      const SceneNode& texture_node = (*nodes)[(*texture)[0].node];
      EXPECT_TRUE(node.index >= texture_node.index &&
                  node.index < texture_node.index + texture_node.subtree_nodes);
    }
  }
  for (size_t o = 0; o < seen.size(); ++o) EXPECT_EQ(seen[o], 1) << "object " << o;
}

TEST(SceneArchive, EverySubtreeIsOneContiguousByteRange) {
  ScratchDir dir;
  BuiltScene built = buildSynthetic(dir, "400:40:5");
  auto scene = openScene(built.path);
  ASSERT_TRUE(scene);
  auto nodes = scene->allNodes();
  ASSERT_TRUE(nodes.has_value());
  for (const SceneNode& node : *nodes) {
    // The union of the own blocks of the subtree's nodes is exactly the subtree range, with
    // no gap and no overlap, and every mesh blob and non-coarsest tile inside its own block.
    uint64_t pos = node.subtree.offset_bytes;
    for (uint32_t k = node.index; k < node.index + node.subtree_nodes; ++k) {
      const SceneNode& d = (*nodes)[k];
      EXPECT_EQ(d.own.offset_bytes, pos) << "node " << k << " in subtree of " << node.index;
      pos += d.own.length_bytes;
    }
    EXPECT_EQ(pos, node.subtree.offset_bytes + node.subtree.length_bytes);
  }
  // A whole subtree read once parses node by node from its slices.
  const SceneNode& root = (*nodes)[0];
  std::vector<uint8_t> bytes(root.subtree.length_bytes);
  ASSERT_TRUE(scene->source().read(root.subtree.offset_bytes, bytes).has_value());
  uint64_t meshes = 0;
  for (const SceneNode& node : *nodes) {
    std::span<const uint8_t> own(bytes.data() + (node.own.offset_bytes - root.subtree.offset_bytes),
                                 node.own.length_bytes);
    Result<NodeContents> contents = scene->parseNode(node, own);
    ASSERT_TRUE(contents.has_value()) << contents.error().message;
    for (const SceneMesh& mesh : contents->meshes) {
      EXPECT_GE(mesh.blob.offset_bytes, node.own.offset_bytes + node.head_bytes);
      EXPECT_LE(mesh.blob.offset_bytes + mesh.blob.length_bytes,
                node.own.offset_bytes + node.own.length_bytes);
      ++meshes;
    }
    for (const NodeTexture& texture : contents->textures)
      for (size_t level = 0; level + 1 < texture.levels.size(); ++level)
        for (const TileEntry& e : texture.levels[level])
          if (e.kind == TileKind::kEncoded) {
            EXPECT_GE(e.offset_bytes, node.own.offset_bytes);
            EXPECT_LE(e.offset_bytes + e.length_bytes,
                      node.own.offset_bytes + node.own.length_bytes);
          }
  }
  EXPECT_EQ(meshes, scene->summary().meshes);
}

TEST(SceneArchive, TexturesAreOrdinaryImagesForTheVersion10Reader) {
  ScratchDir dir;
  BuiltScene built = buildSynthetic(dir, "300:30:6");
  auto archive = Archive::openFile(built.path);
  ASSERT_TRUE(archive.has_value()) << archive.error().message;
  auto scene = openScene(built.path);
  ASSERT_TRUE(scene);
  EXPECT_EQ((*archive)->images().size(), scene->summary().textures);
  VerifyReport report = (*archive)->verify(true);
  EXPECT_TRUE(report.ok()) << (report.faults.empty() ? "" : report.faults[0]);
  // Every texture's coarsest level reads the same through both readers.
  auto textures = scene->textures(0, scene->summary().textures);
  ASSERT_TRUE(textures.has_value());
  for (const SceneTexture& texture : *textures) {
    const uint32_t level = texture.info.level_count - 1;
    Result<Image> ours = scene->readCoarsest(texture);
    ASSERT_TRUE(ours.has_value()) << ours.error().message;
    Result<Image> theirs = (*archive)->readTile({texture.image, level, 0, 0});
    ASSERT_TRUE(theirs.has_value()) << theirs.error().message;
    EXPECT_EQ(ours->texels, theirs->texels) << "texture " << texture.index;
  }
}

// meshoptimizer's index codec may rotate a triangle's three indices (its winding is kept):
// triangles compare after rotating their smallest index first.
std::vector<uint32_t> canonicalTriangles(const std::vector<uint32_t>& indices) {
  std::vector<uint32_t> out;
  for (size_t t = 0; t + 2 < indices.size(); t += 3) {
    const uint32_t* v = &indices[t];
    const int first = v[0] <= v[1] && v[0] <= v[2] ? 0 : v[1] <= v[2] ? 1 : 2;
    for (int k = 0; k < 3; ++k) out.push_back(v[(first + k) % 3]);
  }
  return out;
}

TEST(SceneArchive, MeshesRoundTripWithEveryGeometryCodec) {
  ScratchDir dir;
  std::map<GeometryCodec, uint64_t> stored;
  std::vector<MeshData> reference;
  for (GeometryCodec codec : {GeometryCodec::kRaw, GeometryCodec::kZstd, GeometryCodec::kMeshopt}) {
    BuiltScene built = buildSynthetic(dir, "200:20:7", codec,
                                      std::string("g-") + geometryCodecName(codec) + ".tess");
    stored[codec] = built.report.geometry_stored_bytes;
    auto scene = openScene(built.path);
    ASSERT_TRUE(scene);
    auto nodes = scene->allNodes();
    ASSERT_TRUE(nodes.has_value());
    std::vector<MeshData> meshes;
    for (const SceneNode& node : *nodes) {
      auto contents = scene->readNode(node);
      ASSERT_TRUE(contents.has_value());
      for (const SceneMesh& mesh : contents->meshes) {
        Result<MeshData> data = scene->readMesh(mesh);
        ASSERT_TRUE(data.has_value()) << data.error().message;
        meshes.push_back(*data);
      }
    }
    if (reference.empty()) reference = meshes;
    ASSERT_EQ(meshes.size(), reference.size());
    for (size_t m = 0; m < meshes.size(); ++m) {
      EXPECT_EQ(meshes[m].positions, reference[m].positions);
      EXPECT_EQ(meshes[m].normals, reference[m].normals);
      EXPECT_EQ(meshes[m].uv0, reference[m].uv0);
      EXPECT_EQ(canonicalTriangles(meshes[m].indices), canonicalTriangles(reference[m].indices));
    }
  }
  EXPECT_LT(stored[GeometryCodec::kMeshopt], stored[GeometryCodec::kRaw]);
  EXPECT_LT(stored[GeometryCodec::kZstd], stored[GeometryCodec::kRaw]);
  std::printf("geometry bytes: raw %llu, zstd %llu, meshopt %llu\n",
              (unsigned long long)stored[GeometryCodec::kRaw],
              (unsigned long long)stored[GeometryCodec::kZstd],
              (unsigned long long)stored[GeometryCodec::kMeshopt]);
}

TEST(SceneArchive, BuildIsDeterministic) {
  ScratchDir dir;
  BuiltScene a = buildSynthetic(dir, "250:25:8", GeometryCodec::kMeshopt, "a.tess");
  BuiltScene b = buildSynthetic(dir, "250:25:8", GeometryCodec::kMeshopt, "b.tess");
  EXPECT_EQ(test::readFileBytes(a.path), test::readFileBytes(b.path));
}

TEST(SceneArchive, PromotionAvoidsCopiesOfSharedTextures) {
  ScratchDir dir;
  BuiltScene built = buildSynthetic(dir, "800:80:9");
  const PromotionStats& p = built.report.promotion;
  EXPECT_EQ(p.stored, built.report.summary.textures);
  EXPECT_GT(p.shared, 0u);
  EXPECT_EQ(p.copies_avoided, p.leaf_copies - p.stored);
  EXPECT_GT(p.copies_avoided, 0u);
  uint64_t at_depth = 0;
  for (uint64_t n : p.stored_at_depth) at_depth += n;
  EXPECT_EQ(at_depth, p.stored);
  EXPECT_GT(p.stored_at_depth[0], 0u) << "the global textures reach the root";
}

TEST(SceneArchive, OpeningAnImageArchiveSaysItHasNoScene) {
  ScratchDir dir;
  BuiltScene built = buildSynthetic(dir, "20:2:1");
  // Patch the header into a 1.0 header with the same fields: the scene reference vanishes.
  std::vector<uint8_t> bytes = test::readFileBytes(built.path);
  auto header = detail::decodeHeader(bytes, "x");
  ASSERT_TRUE(header.has_value());
  header->version_minor = 0;
  std::vector<uint8_t> plain = detail::encodeHeader(*header);
  std::copy(plain.begin(), plain.end(), bytes.begin());
  auto scene = SceneArchive::open(makeMemorySource(bytes, "plain.tess"));
  ASSERT_FALSE(scene.has_value());
  EXPECT_EQ(scene.error().code, ErrorCode::kNotFound);
  EXPECT_NE(scene.error().message.find("plain.tess"), std::string::npos);
}

TEST(SceneArchive, CorruptNodeHeadIsCaughtByItsChecksum) {
  ScratchDir dir;
  BuiltScene built = buildSynthetic(dir, "50:5:2");
  auto scene = openScene(built.path);
  ASSERT_TRUE(scene);
  auto root = scene->node(0);
  ASSERT_TRUE(root.has_value());
  std::vector<uint8_t> bytes = test::readFileBytes(built.path);
  bytes[root->own.offset_bytes + 3] ^= 0x40;
  auto corrupt = SceneArchive::open(makeMemorySource(bytes, "corrupt.tess"));
  ASSERT_TRUE(corrupt.has_value());
  auto node = (*corrupt)->node(0);
  ASSERT_TRUE(node.has_value());
  auto contents = (*corrupt)->readNode(*node);
  ASSERT_FALSE(contents.has_value());
  EXPECT_NE(contents.error().message.find("node 0: head checksum mismatch"), std::string::npos)
      << contents.error().message;
}

}  // namespace
}  // namespace tessera
