// Mixed archives through the command line: `tessera brushes`, `tessera build --procedural`,
// and `tessera info` counting procedural tiles per level as procedural.
#include <filesystem>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <tessera/archive.h>

#include "run_program.h"
#include "support/archive_fixture.h"
#include "support/test_images.h"

namespace tessera {
namespace {

/// A w x h RGBA image: opaque colour varying across it, or a disc with soft alpha.
Image brushImage(uint32_t side, bool disc) {
  Image image(side, side, 4);
  for (uint32_t y = 0; y < side; ++y) {
    for (uint32_t x = 0; x < side; ++x) {
      uint8_t* t = &image.texels[(size_t(y) * side + x) * 4];
      t[0] = uint8_t(x * 255 / side);
      t[1] = uint8_t(y * 255 / side);
      t[2] = uint8_t((x ^ y) * 8);
      const double d = std::hypot(x + 0.5 - side / 2.0, y + 0.5 - side / 2.0) / (side / 2.0);
      t[3] = disc ? uint8_t(std::clamp((1 - d) * 3, 0.0, 1.0) * 255) : 255;
    }
  }
  return image;
}

TEST(ProceduralCli, InfoCountsProceduralTilesPerLevel) {
  const std::string dir = test::testTempDir(), log = dir + "run";
  const std::string db = dir + "world.sqlite", archive_path = dir + "mixed.tess";
  ASSERT_EQ(test::writeImagePng(dir + "base.png", brushImage(32, false)), "");
  ASSERT_EQ(test::writeImagePng(dir + "stamp.png", brushImage(16, true)), "");
  auto ok = [&](const std::vector<std::string>& args) {
    test::RunResult result = test::runTessera(args, log);
    EXPECT_EQ(result.exit_code, 0) << result.err;
    return result;
  };
  ok({"brushes", "init", db, "--size", "512x384"});
  ok({"brushes", "add-brush", db, "--name", "base", "--image", dir + "base.png"});
  ok({"brushes", "add-brush", db, "--name", "stamp", "--image", dir + "stamp.png", "--blend",
      "multiply"});
  ok({"brushes", "generate", db, "--count", "300", "--seed", "29"});
  ok({"build", "--procedural", db, "-o", archive_path, "--tile", "64", "--codec", "zstd",
      "--threads", "2", "--quiet"});
  const test::RunResult info = ok({"info", archive_path, "--json"});
  const nlohmann::json json = nlohmann::json::parse(info.out, nullptr, false);
  ASSERT_FALSE(json.is_discarded()) << info.out;
  const nlohmann::json& table = json["images"][0]["level_table"];

  // Each level's counts are the directory's kinds, procedural ones included.
  auto archive = Archive::openFile(archive_path);
  ASSERT_TRUE(archive) << archive.error().message;
  const ImageInfo& image = (*archive)->images()[0];
  ASSERT_EQ(table.size(), image.level_count);
  uint64_t procedural_total = 0;
  for (uint32_t level = 0; level < image.level_count; ++level) {
    uint64_t procedural = 0, empty = 0, page_bytes = 0;
    for (uint32_t y = 0; y < image.tilesY(level); ++y) {
      for (uint32_t x = 0; x < image.tilesX(level); ++x) {
        const TileEntry entry = *(*archive)->tileEntry({0, level, x, y});
        if (entry.kind == TileKind::kProcedural) ++procedural, page_bytes += entry.length_bytes;
        if (entry.kind == TileKind::kEmpty) ++empty;
      }
    }
    const nlohmann::json& row = table[level];
    EXPECT_EQ(row["procedural"].get<uint64_t>(), procedural) << "level " << level;
    EXPECT_EQ(row["empty"].get<uint64_t>(), empty) << "level " << level;
    EXPECT_EQ(row["page_bytes"].get<uint64_t>(), page_bytes) << "level " << level;
    EXPECT_EQ(row["encoded"].get<uint64_t>() + row["uniform"].get<uint64_t>() +
                  row["procedural"].get<uint64_t>() + row["empty"].get<uint64_t>(),
              uint64_t(image.tilesX(level)) * image.tilesY(level));
    procedural_total += procedural;
  }
  EXPECT_GT(procedural_total, 0u) << "the build kept no tile procedural: the test shows nothing";

  const test::RunResult text = ok({"info", archive_path});
  EXPECT_NE(text.out.find("procedural"), std::string::npos) << text.out;
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace tessera
