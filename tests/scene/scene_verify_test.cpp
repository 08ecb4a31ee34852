// verifyScene: a clean scene archive passes; a flipped byte in a node head, a mesh blob or the
// node table is a fault naming the archive and the item (or refused at open).
#include <tessera/scene.h>

#include <gtest/gtest.h>

#include <tessera/archive.h>
#include <tessera/scene_build.h>

#include "scene/scene_test_support.h"

namespace tessera {
namespace {

using test::ScratchDir;

std::string buildCity(const ScratchDir& dir) {
  return test::buildSyntheticCity(dir, "200:20:3");
}

SceneVerifyReport verifyBytes(const std::vector<uint8_t>& bytes) {
  auto source = makeMemorySource(bytes, "city.tess");
  auto archive = Archive::open(source);
  EXPECT_TRUE(archive.has_value());
  auto scene = SceneArchive::open(source);
  EXPECT_TRUE(scene.has_value());
  if (!archive || !scene) return {};
  return verifyScene(**scene, (*archive)->images(), true);
}

std::string allFaults(const SceneVerifyReport& report) {
  std::string out;
  for (const std::string& fault : report.faults) out += fault + "\n";
  return out;
}

TEST(SceneVerify, CleanArchivePassesAndEveryPartIsWalked) {
  ScratchDir dir;
  const std::vector<uint8_t> bytes = test::readFileBytes(buildCity(dir));
  auto scene = SceneArchive::open(makeMemorySource(bytes, "city.tess"));
  ASSERT_TRUE(scene.has_value());
  const SceneVerifyReport report = verifyBytes(bytes);
  EXPECT_TRUE(report.ok()) << allFaults(report);
  EXPECT_EQ(report.nodes_checked, (*scene)->summary().nodes);
  EXPECT_EQ(report.objects_checked, 200u);
  EXPECT_EQ(report.meshes_checked, (*scene)->summary().meshes);
  EXPECT_EQ(report.textures_checked, (*scene)->summary().textures);
}

TEST(SceneVerify, CorruptNodeHeadMeshBlobAndNodeTableAreFaults) {
  ScratchDir dir;
  const std::vector<uint8_t> clean = test::readFileBytes(buildCity(dir));
  auto scene = SceneArchive::open(makeMemorySource(clean, "city.tess"));
  ASSERT_TRUE(scene.has_value());
  auto nodes = (*scene)->allNodes();
  ASSERT_TRUE(nodes.has_value());
  // A leaf's head.
  const SceneNode& leaf = nodes->back();
  ASSERT_TRUE(leaf.isLeaf());
  std::vector<uint8_t> bytes = clean;
  bytes[leaf.own.offset_bytes + leaf.head_bytes / 2] ^= 0x5A;
  SceneVerifyReport report = verifyBytes(bytes);
  EXPECT_FALSE(report.ok());
  EXPECT_NE(allFaults(report).find("city.tess"), std::string::npos) << allFaults(report);
  EXPECT_NE(allFaults(report).find("node " + std::to_string(leaf.index)), std::string::npos)
      << allFaults(report);
  // A mesh blob.
  SceneMesh mesh;
  for (const SceneNode& node : *nodes) {
    auto contents = (*scene)->readNode(node);
    ASSERT_TRUE(contents.has_value());
    if (!contents->meshes.empty()) {
      mesh = contents->meshes[0];
      break;
    }
  }
  ASSERT_GT(mesh.blob.length_bytes, 0u);
  bytes = clean;
  bytes[mesh.blob.offset_bytes + mesh.blob.length_bytes / 2] ^= 0x5A;
  report = verifyBytes(bytes);
  EXPECT_EQ(report.fault_count, 1u) << allFaults(report);
  EXPECT_NE(allFaults(report).find("mesh " + std::to_string(mesh.index)), std::string::npos)
      << allFaults(report);
  // The node table: refused at open, or a fault of the walk.
  const FileRange table = (*scene)->nodeTableRange();
  bytes = clean;
  bytes[table.offset_bytes + table.length_bytes / 2] ^= 0x5A;
  auto source = makeMemorySource(bytes, "city.tess");
  auto broken = SceneArchive::open(source);
  auto archive = Archive::open(source);
  const bool refused = !broken.has_value() || !archive.has_value();
  EXPECT_TRUE(refused || !verifyScene(**broken, (*archive)->images(), false).ok());
}

}  // namespace
}  // namespace tessera
