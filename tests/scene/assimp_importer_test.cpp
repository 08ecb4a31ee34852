// Scenes through Assimp: an OBJ with a material library, and its bad inputs.
#include <fstream>

#include <gtest/gtest.h>

#include <tessera/scene.h>
#include <tessera/scene_build.h>

#include "scene/scene_test_support.h"

namespace tessera {
namespace {

using test::ScratchDir;

// Two textured quads sharing one material and one untextured.
std::string writeObj(const ScratchDir& dir, const std::string& texture) {
  std::ofstream(dir.file("street.mtl"))
      << "newmtl brick\nKd 1 1 1\nmap_Kd " << texture << "\nnewmtl plain\nKd 0.5 0.5 0.5\n";
  std::ofstream(dir.file("street.obj"))
      << "mtllib street.mtl\n"
         "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 5 0 0\nv 6 0 0\nv 6 1 0\nv 5 1 0\n"
         "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
         "o a\nusemtl brick\nf 1/1 2/2 3/3 4/4\n"
         "o b\nusemtl brick\nf 5/1 6/2 7/3 8/4\n";
  return dir.file("street.obj");
}

SceneBuildOptions options(const std::string& input, const std::string& output) {
  SceneBuildOptions o;
  o.input = input;
  o.output = output;
  o.tile_size_px = 64;
  o.threads = 2;
  return o;
}

TEST(AssimpImporter, BuildsAnObjWithItsMaterialLibrary) {
  ScratchDir dir;
  test::writeTestPng(dir.file("brick.png"), 128, 128, 4);
  Result<SceneBuildReport> report =
      buildScene(options(writeObj(dir, "brick.png"), dir.file("street.tess")));
  ASSERT_TRUE(report.has_value()) << report.error().message;
  EXPECT_EQ(report->importer, "assimp");
  EXPECT_EQ(report->summary.textures, 1u);
  EXPECT_GE(report->summary.objects, 1u);
  auto scene = SceneArchive::openFile(dir.file("street.tess"));
  ASSERT_TRUE(scene.has_value());
  auto root = (*scene)->node(0);
  ASSERT_TRUE(root.has_value());
  EXPECT_TRUE((*scene)->readNode(*root).has_value());
}

TEST(AssimpImporter, MissingTextureNamesTheFile) {
  ScratchDir dir;
  Result<SceneBuildReport> report =
      buildScene(options(writeObj(dir, "gone.png"), dir.file("street.tess")));
  ASSERT_FALSE(report.has_value());
  EXPECT_NE(report.error().message.find("street.obj"), std::string::npos) << report.error().message;
  EXPECT_NE(report.error().message.find("gone.png"), std::string::npos) << report.error().message;
  EXPECT_FALSE(std::filesystem::exists(dir.file("street.tess")));
}

TEST(AssimpImporter, UnreadableFileNamesIt) {
  ScratchDir dir;
  std::ofstream(dir.file("junk.dae")) << "<COLLADA this is not";
  Result<SceneBuildReport> report = buildScene(options(dir.file("junk.dae"), dir.file("j.tess")));
  ASSERT_FALSE(report.has_value());
  EXPECT_NE(report.error().message.find("junk.dae"), std::string::npos) << report.error().message;
}

}  // namespace
}  // namespace tessera
