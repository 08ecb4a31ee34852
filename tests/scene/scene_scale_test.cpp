// The generator at the scale: 100,000 objects and 10,000 textures build with bounded
// memory (the peak resident set stays under a fixed bound whatever the texture count, since
// payloads go through a spool file and only tile entries stay in memory), and the archive
// opens with one read and reads any node with two more.
#include <sys/resource.h>

#include <gtest/gtest.h>

#include <tessera/scene.h>
#include <tessera/scene_build.h>

#include "scene/scene_test_support.h"

namespace tessera {
namespace {

// AddressSanitizer's shadow memory and quarantine add hundreds of MiB to the resident set.
#if defined(__SANITIZE_ADDRESS__)
constexpr double kPeakBoundMiB = 2048;
#else
constexpr double kPeakBoundMiB = 512;
#endif

TEST(SceneScale, HundredThousandObjectsTenThousandTexturesInBoundedMemory) {
  test::ScratchDir dir;
  SceneBuildOptions options;
  options.input = "synthetic-scene:100000:10000:1";
  options.output = dir.file("big.tess");
  options.tile_size_px = 64;
  options.threads = 2;
  Result<SceneBuildReport> report = buildScene(options);
  ASSERT_TRUE(report.has_value()) << report.error().message;
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  const double peak_mib = usage.ru_maxrss / 1024.0;
  std::printf(
      "100,000 objects, 10,000 textures: %u nodes, depth %u, %.1f MiB archive in %.1f s, "
      "peak RSS %.0f MiB; promotion: %llu leaf copies, %llu stored, %llu avoided\n",
      report->summary.nodes, report->summary.tree_depth, report->output_bytes / 1048576.0,
      report->elapsed_s, peak_mib, (unsigned long long)report->promotion.leaf_copies,
      (unsigned long long)report->promotion.stored,
      (unsigned long long)report->promotion.copies_avoided);
  EXPECT_EQ(report->summary.objects, 100000u);
  EXPECT_EQ(report->summary.textures, 10000u);
  EXPECT_LT(peak_mib, kPeakBoundMiB) << "the build's memory should not grow with the textures";

  auto file = openFileSource(options.output);
  ASSERT_TRUE(file.has_value());
  auto counter = std::make_shared<test::CountingSource>(*file);
  auto scene = SceneArchive::open(counter);
  ASSERT_TRUE(scene.has_value()) << scene.error().message;
  EXPECT_EQ(counter->reads, 1u);
  for (uint32_t i : {0u, (*scene)->summary().nodes / 2, (*scene)->summary().nodes - 1}) {
    const uint64_t before = counter->reads;
    auto node = (*scene)->node(i);
    ASSERT_TRUE(node.has_value());
    ASSERT_TRUE((*scene)->readNode(*node).has_value());
    EXPECT_LE(counter->reads - before, 2u) << "node " << i;
  }
}

}  // namespace
}  // namespace tessera
