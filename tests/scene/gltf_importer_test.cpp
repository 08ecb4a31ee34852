// glTF scenes through buildScene: good files (external and embedded images, shared textures
// and meshes) and every bad input of issue 28 item 8, each a clear error naming the file and
// the item, with nothing left at the output path.
#include <cmath>
#include <limits>

#include <gtest/gtest.h>

#include <tessera/scene.h>
#include <tessera/scene_build.h>

#include "scene/scene_test_support.h"

namespace tessera {
namespace {

using test::GltfBuilder;
using test::ScratchDir;

Result<SceneBuildReport> build(const std::string& input, const std::string& output) {
  SceneBuildOptions options;
  options.input = input;
  options.output = output;
  options.tile_size_px = 64;
  options.threads = 2;
  options.leaf_capacity = 2;
  options.max_children = 2;
  return buildScene(options);
}

// A glTF city block: `count` quads in a row; quad k uses image k % images (so images are
// shared between distant quads) and one shared mesh per material.
GltfBuilder cityBlock(const ScratchDir& dir, int count, int images, bool embedded) {
  GltfBuilder g;
  std::vector<int> meshes;
  for (int i = 0; i < images; ++i) {
    const std::string name = "tex" + std::to_string(i) + ".png";
    test::writeTestPng(dir.file(name), 96 + 32 * i, 80, uint32_t(i));
    const int image = embedded ? g.addImageBytes(test::readFileBytes(dir.file(name)), "image/png")
                               : g.addImageUri(name);
    meshes.push_back(g.addQuadMesh(g.addMaterial(g.addTexture(image))));
  }
  std::vector<int> roots;
  for (int k = 0; k < count; ++k) roots.push_back(g.addNode(meshes[k % images], float(k * 3), 0));
  g.setRoots(roots);
  return g;
}

void expectFailure(const Result<SceneBuildReport>& result, const ScratchDir& dir,
                   const std::string& output, const std::vector<std::string>& words) {
  ASSERT_FALSE(result.has_value()) << "the build should fail";
  for (const std::string& word : words)
    EXPECT_NE(result.error().message.find(word), std::string::npos)
        << "'" << word << "' missing from: " << result.error().message;
  EXPECT_FALSE(std::filesystem::exists(output)) << "a failed build left " << output;
  for (const std::string& name : dir.files())
    EXPECT_EQ(name.find(".tess"), std::string::npos) << "temporary left behind: " << name;
}

TEST(GltfImporter, BuildsExternalImagesAndKeepsSharing) {
  ScratchDir dir;
  GltfBuilder g = cityBlock(dir, 12, 3, false);
  const std::string path = g.writeGltf(dir, "block");
  Result<SceneBuildReport> report = build(path, dir.file("block.tess"));
  ASSERT_TRUE(report.has_value()) << report.error().message;
  EXPECT_EQ(report->importer, "gltf");
  EXPECT_EQ(report->summary.objects, 12u);
  EXPECT_EQ(report->summary.textures, 3u) << "a shared image is one texture";
  EXPECT_EQ(report->summary.meshes, 3u) << "a shared mesh is one mesh";
  EXPECT_EQ(report->promotion.stored, 3u);
  EXPECT_GT(report->promotion.copies_avoided, 0u);
  auto scene = SceneArchive::openFile(dir.file("block.tess"));
  ASSERT_TRUE(scene.has_value()) << scene.error().message;
  auto textures = (*scene)->textures(0, 3);
  ASSERT_TRUE(textures.has_value());
  for (const SceneTexture& t : *textures) EXPECT_EQ(t.users, 4u);
}

TEST(GltfImporter, BuildsAGlbWithEmbeddedImages) {
  ScratchDir dir;
  GltfBuilder g = cityBlock(dir, 6, 2, true);
  const std::string path = g.writeGlb(dir, "block");
  Result<SceneBuildReport> report = build(path, dir.file("block.tess"));
  ASSERT_TRUE(report.has_value()) << report.error().message;
  EXPECT_EQ(report->summary.textures, 2u);
  EXPECT_EQ(report->summary.objects, 6u);
}

// glTF allows 16-bit PNGs; scene textures are drawn as 8-bit texels, so the build narrows them
// (rounding) instead of refusing or misreading them.
TEST(GltfImporter, SixteenBitPngTexturesAreNarrowedToEightBits) {
  ScratchDir dir;
  test::PngSpec spec;
  spec.width_px = 70;
  spec.height_px = 50;
  spec.colour = test::PngColour::kGray;
  spec.bit_depth = 16;
  // test::writePng widens each byte b to 16 bits as b * 257; 0xC8C8 narrows back to 0xC8.
  ASSERT_EQ(test::writePng(dir.file("deep.png"), spec, std::vector<uint8_t>(70 * 50, 0xC8)), "");
  GltfBuilder g;
  g.setRoots(
      {g.addNode(g.addQuadMesh(g.addMaterial(g.addTexture(g.addImageUri("deep.png")))), 0, 0)});
  const std::string path = g.writeGltf(dir, "deep");
  Result<SceneBuildReport> report = build(path, dir.file("deep.tess"));
  ASSERT_TRUE(report.has_value()) << report.error().message;
  auto scene = SceneArchive::openFile(dir.file("deep.tess"));
  ASSERT_TRUE(scene.has_value()) << scene.error().message;
  auto textures = (*scene)->textures(0, 1);
  ASSERT_TRUE(textures.has_value() && textures->size() == 1);
  EXPECT_EQ((*textures)[0].info.sample_type, SampleType::kU8);
  Result<Image> coarsest = (*scene)->readCoarsest((*textures)[0]);
  ASSERT_TRUE(coarsest.has_value()) << coarsest.error().message;
  for (uint8_t texel : coarsest->texels) ASSERT_EQ(texel, 0xC8);
}

TEST(GltfImporter, MissingTextureFileNamesFileAndImage) {
  ScratchDir dir;
  GltfBuilder g = cityBlock(dir, 4, 2, false);
  std::filesystem::remove(dir.file("tex1.png"));
  const std::string path = g.writeGltf(dir, "block");
  expectFailure(build(path, dir.file("out.tess")), dir, dir.file("out.tess"),
                {"block.gltf", "image 1", "tex1.png", "not found"});
}

TEST(GltfImporter, UnsupportedEmbeddedImageNamesIt) {
  ScratchDir dir;
  GltfBuilder g = cityBlock(dir, 2, 1, true);
  const std::vector<uint8_t> ktx2 = {0xAB, 'K',  'T',  'X',  ' ',  '2',
                                     '0',  0xBB, 0x0D, 0x0A, 0x1A, 0x0A};
  const int image = g.addImageBytes(ktx2, "image/ktx2");
  g.setRoots({0, g.addNode(g.addQuadMesh(g.addMaterial(g.addTexture(image))), 9, 9)});
  const std::string path = g.writeGlb(dir, "ktx");
  expectFailure(build(path, dir.file("out.tess")), dir, dir.file("out.tess"),
                {"ktx.glb", "image 1", "image/ktx2", "not PNG or JPEG"});
}

TEST(GltfImporter, CyclicNodeGraphIsRefused) {
  ScratchDir dir;
  GltfBuilder g = cityBlock(dir, 2, 1, false);
  g.doc["nodes"][0]["children"] = {1};
  g.doc["nodes"][1]["children"] = {0};
  g.setRoots({0});
  const std::string path = g.writeGltf(dir, "cycle");
  expectFailure(build(path, dir.file("out.tess")), dir, dir.file("out.tess"),
                {"cycle.gltf", "node", "cycle"});
}

TEST(GltfImporter, AbsurdlyDeepNodeGraphIsRefused) {
  ScratchDir dir;
  GltfBuilder g = cityBlock(dir, 1, 1, false);
  int previous = 0;
  for (int i = 0; i < 1000; ++i) {
    const int node = g.addNode(-1, 0, 0);
    g.doc["nodes"][previous]["children"] = {node};
    previous = node;
  }
  g.setRoots({0});
  const std::string path = g.writeGltf(dir, "deep");
  expectFailure(build(path, dir.file("out.tess")), dir, dir.file("out.tess"),
                {"deep.gltf", "nested", "256"});
}

TEST(GltfImporter, TwoToThe31IndicesAreRefusedBeforeAllocating) {
  ScratchDir dir;
  GltfBuilder g = cityBlock(dir, 1, 1, false);
  g.doc["accessors"][2]["count"] = 2147483648ull;
  const std::string path = g.writeGltf(dir, "huge");
  expectFailure(build(path, dir.file("out.tess")), dir, dir.file("out.tess"),
                {"huge.gltf", "mesh 0", "2147483648 indices"});
}

TEST(GltfImporter, NonFiniteVertexNamesMeshAndVertex) {
  ScratchDir dir;
  GltfBuilder g = cityBlock(dir, 1, 1, false);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(g.bin.data() + 4 * 4, &nan, 4);  // vertex 1, x
  const std::string path = g.writeGltf(dir, "nan");
  expectFailure(build(path, dir.file("out.tess")), dir, dir.file("out.tess"),
                {"nan.gltf", "mesh 0", "vertex 1", "non-finite"});
}

TEST(GltfImporter, TextureIndexOutOfRangeNamesTheMaterial) {
  ScratchDir dir;
  GltfBuilder g = cityBlock(dir, 1, 1, false);
  g.doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["index"] = 7;
  const std::string path = g.writeGltf(dir, "range");
  expectFailure(build(path, dir.file("out.tess")), dir, dir.file("out.tess"),
                {"range.gltf", "material 0", "texture 7", "out of range"});
}

TEST(GltfImporter, TruncatedGlbIsRefusedAtEveryCut) {
  ScratchDir dir;
  GltfBuilder g = cityBlock(dir, 3, 1, true);
  const std::vector<uint8_t> whole = test::readFileBytes(g.writeGlb(dir, "whole"));
  for (size_t cut :
       {size_t(0), size_t(5), size_t(12), size_t(20), whole.size() / 2, whole.size() - 1}) {
    SCOPED_TRACE(testing::Message() << "cut at " << cut);
    test::writeFileBytes(dir.file("cut.glb"), {whole.begin(), whole.begin() + cut});
    expectFailure(build(dir.file("cut.glb"), dir.file("out.tess")), dir, dir.file("out.tess"),
                  {"cut.glb"});
  }
}

TEST(GltfImporter, MissingSceneFileIsNotFound) {
  ScratchDir dir;
  Result<SceneBuildReport> result = build(dir.file("nowhere.gltf"), dir.file("out.tess"));
  ASSERT_FALSE(result.has_value());
  EXPECT_EQ(result.error().code, ErrorCode::kNotFound);
  EXPECT_NE(result.error().message.find("nowhere.gltf"), std::string::npos);
}

TEST(GltfImporter, FailedBuildLeavesAnExistingOutputUntouched) {
  ScratchDir dir;
  test::writeFileBytes(dir.file("keep.tess"), {1, 2, 3});
  GltfBuilder g = cityBlock(dir, 2, 1, false);
  std::filesystem::remove(dir.file("tex0.png"));
  ASSERT_FALSE(build(g.writeGltf(dir, "b"), dir.file("keep.tess")).has_value());
  EXPECT_EQ(test::readFileBytes(dir.file("keep.tess")), (std::vector<uint8_t>{1, 2, 3}));
}

}  // namespace
}  // namespace tessera
