// The `tessera` command line, run as a real process: build -> info --json -> verify -> damage
// -> verify names the tile -> extract; usage errors, --help, bad inputs and failed outputs.
#include <spawn.h>
#include <sys/wait.h>
#include <fcntl.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <tessera/archive.h>
#include <tessera/scene.h>
#include <tessera/stream.h>

#include "builder/band_reader.h"
#include "codecs/decode.h"
#include "support/archive_fixture.h"
#include "support/nginx_server.h"
#include "support/reference_pyramid.h"
#include "support/sanitizers.h"
#include "support/test_images.h"
#include "run_program.h"

extern char** environ;

namespace tessera {
namespace {

using test::runProgram;
using test::RunResult;
using test::runTessera;
using test::slurp;

// This process's environment without the variables that name a display.
std::vector<std::string> environmentWithoutDisplay() {
  std::vector<std::string> env;
  for (char** entry = environ; *entry; ++entry) {
    std::string text = *entry;
    if (text.rfind("DISPLAY=", 0) == 0 || text.rfind("WAYLAND_DISPLAY=", 0) == 0) continue;
    env.push_back(text);
  }
  return env;
}

// The directory on PATH holding `name`, or "" when none does.
std::string findOnPath(const std::string& name) {
  const char* path = std::getenv("PATH");
  std::stringstream dirs(path ? path : "");
  std::string dir;
  while (std::getline(dirs, dir, ':')) {
    std::filesystem::path candidate = std::filesystem::path(dir) / name;
    if (::access(candidate.c_str(), X_OK) == 0) return candidate.string();
  }
  return "";
}

std::vector<std::string> listDir(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(dir))
    names.push_back(entry.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

class Cli : public testing::Test {
 protected:
  void SetUp() override {
    dir_ = test::testTempDir();
    logs_ = dir_ + "logs/run";
    std::filesystem::create_directories(dir_ + "logs");
    work_ = dir_ + "work/";
    std::filesystem::create_directories(work_);
  }
  RunResult run(const std::vector<std::string>& args) { return runTessera(args, logs_); }
  std::string dir_, logs_, work_;
};

TEST_F(Cli, BuildInfoVerifyCorruptVerifyExtract) {
  const std::string archive_path = work_ + "a.tess";
  RunResult built = run({"build", "synthetic:300x200:4:4", "-o", archive_path, "--tile", "64",
                         "--border", "2", "--codec", "zstd", "--threads", "2", "--quiet"});
  ASSERT_EQ(built.exit_code, 0) << built.err;

  RunResult info = run({"info", archive_path, "--json"});
  ASSERT_EQ(info.exit_code, 0) << info.err;
  nlohmann::json json = nlohmann::json::parse(info.out, nullptr, false);
  ASSERT_FALSE(json.is_discarded()) << info.out;
  EXPECT_EQ(json["path"], archive_path);
  EXPECT_EQ(json["file_bytes"].get<uint64_t>(), std::filesystem::file_size(archive_path));
  ASSERT_EQ(json["images"].size(), 1u);
  const nlohmann::json& image = json["images"][0];
  EXPECT_EQ(image["width"], 300);
  EXPECT_EQ(image["height"], 200);
  EXPECT_EQ(image["channels"], 4);
  EXPECT_EQ(image["tile_size"], 64);
  EXPECT_EQ(image["border"], 2);
  EXPECT_EQ(image["levels"], levelCountFor(300, 200, 64));
  EXPECT_EQ(image["codec"], "zstd");
  ASSERT_EQ(image["level_table"].size(), levelCountFor(300, 200, 64));
  EXPECT_EQ(image["level_table"][0]["tiles_x"], 5);
  EXPECT_EQ(image["level_table"][0]["tiles_y"], 4);
  const nlohmann::json& level0 = image["level_table"][0];
  EXPECT_EQ(
      level0["encoded"].get<int>() + level0["uniform"].get<int>() + level0["empty"].get<int>(), 20);

  RunResult verified = run({"verify", archive_path});
  EXPECT_EQ(verified.exit_code, 0) << verified.err;
  EXPECT_NE(verified.out.find("OK"), std::string::npos) << verified.out;

  // Damage one payload byte of an encoded tile.
  auto archive = Archive::openFile(archive_path);
  ASSERT_TRUE(archive);
  TileId victim{};
  TileEntry entry;
  bool found = false;
  for (uint32_t y = 0; y < 4 && !found; ++y)
    for (uint32_t x = 0; x < 5 && !found; ++x)
      if ((entry = *(*archive)->tileEntry({0, 0, x, y})).kind == TileKind::kEncoded)
        victim = {0, 0, x, y}, found = true;
  ASSERT_TRUE(found);
  // Extract before damaging, to compare with the reader.
  RunResult tile_png =
      run({"extract", archive_path, "--level", "0", "--tile",
           std::to_string(victim.x) + "," + std::to_string(victim.y), "-o", work_ + "tile.png"});
  ASSERT_EQ(tile_png.exit_code, 0) << tile_png.err;
  RunResult rect_png = run({"extract", archive_path, "--level", "1", "--rect", "-5,10,100,60",
                            "--with-padding", "-o", work_ + "rect.png"});
  ASSERT_EQ(rect_png.exit_code, 0) << rect_png.err;
  {
    Image tile = *(*archive)->readTile(victim);
    Image inner(64, 64, 4);
    for (uint32_t y = 0; y < 64; ++y)
      std::copy(tile.row(y + 2) + 2 * 4, tile.row(y + 2) + 66 * 4, inner.row(y));
    EXPECT_EQ(test::firstDifference(inner, test::readImagePng(work_ + "tile.png")), "");
    Image region = *(*archive)->readRegion(0, 1, {-5, 10, 100, 60});
    EXPECT_EQ(test::firstDifference(region, test::readImagePng(work_ + "rect.png")), "");
  }
  archive->reset();

  std::vector<uint8_t> bytes = test::readFileBytes(archive_path);
  bytes[entry.offset_bytes + entry.length_bytes / 2] ^= 0x08;
  ASSERT_TRUE(test::writeFileBytes(archive_path, bytes));
  RunResult damaged = run({"verify", archive_path});
  EXPECT_EQ(damaged.exit_code, 3);
  std::string tile_name =
      "tile (0," + std::to_string(victim.x) + "," + std::to_string(victim.y) + ")";
  EXPECT_NE(damaged.err.find(tile_name), std::string::npos) << damaged.err;
  EXPECT_NE(damaged.out.find("1 fault"), std::string::npos) << damaged.out;
  RunResult damaged_json = run({"verify", archive_path, "--json"});
  EXPECT_EQ(damaged_json.exit_code, 3);
  nlohmann::json report = nlohmann::json::parse(damaged_json.out, nullptr, false);
  ASSERT_FALSE(report.is_discarded()) << damaged_json.out;
  EXPECT_EQ(report["ok"], false);
  EXPECT_EQ(report["fault_count"], 1);

  RunResult bad_extract =
      run({"extract", archive_path, "--tile",
           std::to_string(victim.x) + "," + std::to_string(victim.y), "-o", work_ + "bad.png"});
  EXPECT_NE(bad_extract.exit_code, 0);
  EXPECT_NE(bad_extract.err.find(tile_name), std::string::npos) << bad_extract.err;
  EXPECT_FALSE(std::filesystem::exists(work_ + "bad.png"));
}

// `tessera render` draws the reference picture of an orthographic view. Checked against pixels
// known without the renderer: at 1 texel per pixel with pixel centres on texel centres each
// pixel is its level-0 texel; at 2 texels per pixel, on level-1 texel centres, its level-1
// texel; outside the image transparent black; a 90-degree rotation swaps the axes.
// A split build through the commands the Slurm script runs: `build --part I/N` then `merge`
// equals the single build; a malformed part and a missing part are refused with exit 2.
TEST_F(Cli, SplitBuildMergesIntoTheSingleBuild) {
  const std::vector<std::string> common = {
      "synthetic:300x200:4:3", "--tile", "64", "--border", "1", "--threads", "2", "--quiet"};
  auto build = [&](std::vector<std::string> extra) {
    std::vector<std::string> args = {"build"};
    args.insert(args.end(), common.begin(), common.end());
    args.insert(args.end(), extra.begin(), extra.end());
    return run(args);
  };
  ASSERT_EQ(build({"-o", work_ + "single.tess"}).exit_code, 0);
  for (const char* part : {"1/3", "2/3", "3/3"}) {
    RunResult built = build({"--part", part, "-o", work_ + "part-" + part[0] + ".tess"});
    ASSERT_EQ(built.exit_code, 0) << built.err;
  }
  RunResult bad = build({"--part", "4/3", "-o", work_ + "bad.tess"});
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("4/3"), std::string::npos) << bad.err;
  RunResult missing =
      run({"merge", work_ + "part-1.tess", work_ + "part-3.tess", "-o", work_ + "merged.tess"});
  EXPECT_EQ(missing.exit_code, 2);
  EXPECT_NE(missing.err.find("parts 2"), std::string::npos) << missing.err;
  RunResult merged = run({"merge", work_ + "part-3.tess", work_ + "part-1.tess",
                          work_ + "part-2.tess", "-o", work_ + "merged.tess", "--quiet"});
  ASSERT_EQ(merged.exit_code, 0) << merged.err;
  EXPECT_TRUE(test::readFileBytes(work_ + "single.tess") ==
              test::readFileBytes(work_ + "merged.tess"));
}

// A float TIFF and a 16-bit TIFF through build, info and extract (docs/cli.md, "extract"):
// samples come out as stored, and what cannot hold them is refused with exit 2.
TEST_F(Cli, WideSamplesBuildShowAndExtractAsStored) {
  for (const bool is_float : {true, false}) {
    SCOPED_TRACE(is_float ? "f32" : "u16");
    const std::vector<uint8_t> pixels = test::makeTestPixels(90, 70, 1);
    test::TiffSpec spec{.width_px = 90,
                        .height_px = 70,
                        .samples = 1,
                        .bits = uint16_t(is_float ? 32 : 16),
                        .sample_format = uint16_t(is_float ? 3 : 1),
                        .photometric = 1};
    const std::string source = work_ + "wide.tif", archive_path = work_ + "wide.tess";
    ASSERT_EQ(test::writeTiff(source, spec, pixels), "");
    RunResult jpeg = run({"build", source, "-o", archive_path, "-q"});
    EXPECT_EQ(jpeg.exit_code, 2) << jpeg.err;
    EXPECT_NE(jpeg.err.find("cannot be stored with --codec jpeg; use zdelta"), std::string::npos)
        << jpeg.err;
    RunResult built =
        run({"build", source, "-o", archive_path, "--codec", "zdelta", "--tile", "64", "-q"});
    ASSERT_EQ(built.exit_code, 0) << built.err;
    RunResult info = run({"info", archive_path, "--json"});
    ASSERT_EQ(info.exit_code, 0) << info.err;
    const nlohmann::json described = nlohmann::json::parse(info.out);
    EXPECT_EQ(described["images"][0]["sample_type"], is_float ? "f32" : "u16");
    for (const std::string name : {"rect.tif", "rect.png"}) {
      RunResult extracted =
          run({"extract", archive_path, "--rect", "0,0,90,70", "-o", work_ + name});
      if (is_float && name == "rect.png") {
        EXPECT_EQ(extracted.exit_code, 2) << extracted.err;
        EXPECT_NE(extracted.err.find("PNG cannot hold f32 samples"), std::string::npos);
        continue;
      }
      ASSERT_EQ(extracted.exit_code, 0) << extracted.err;
      auto reader = name == "rect.tif" ? detail::openTiffReader(work_ + name)
                                       : detail::openPngReader(work_ + name);
      ASSERT_TRUE(reader) << reader.error().message;
      std::string error;
      const std::vector<uint8_t> got = test::readAllRows(**reader, 16, &error);
      ASSERT_EQ(got.size(), pixels.size() * (is_float ? 4 : 2)) << error;
      for (size_t i = 0; i < pixels.size(); ++i) {
        if (is_float) {
          float value;
          std::memcpy(&value, got.data() + 4 * i, 4);
          ASSERT_EQ(value, float(pixels[i]) / 255.0f) << name << " " << i;
        } else {
          uint16_t value;
          std::memcpy(&value, got.data() + 2 * i, 2);
          ASSERT_EQ(value, pixels[i] * 257) << name << " " << i;
        }
      }
    }
    // Drawn headless through a display window (docs/rendering.md, "Display window"); the
    // at-rest picture has no CPU reference to be compared with.
    const std::string flown = work_ + "fly-wide";
    RunResult drawn = run({"fly", archive_path, "--path", "zoom", "--duration", "0.2", "--fps",
                           "10", "--viewport", "64x48", "--render", "tile-quads", "--window",
                           is_float ? "0,0.5" : "p1,p99", "--gamma", "0.8", "-q", "--out", flown});
    ASSERT_EQ(drawn.exit_code, 0) << drawn.err;
    const nlohmann::json summary = nlohmann::json::parse(slurp(flown + "/summary.json"));
    EXPECT_TRUE(summary["rest_psnr_db_min"].is_null());
    for (const char* window : {"9,2", "p1", "auto,1"}) {
      RunResult refused = run({"fly", archive_path, "--render", "tile-quads", "--window", window,
                               "-q", "--out", flown});
      EXPECT_EQ(refused.exit_code, 2) << window;
      EXPECT_NE(refused.err.find(std::string("--window: window '") + window + "'"),
                std::string::npos)
          << refused.err;
    }
    RunResult no_gamma =
        run({"fly", archive_path, "--render", "tile-quads", "--gamma", "0", "-q", "--out", flown});
    EXPECT_EQ(no_gamma.exit_code, 2);
    EXPECT_NE(no_gamma.err.find("--gamma"), std::string::npos) << no_gamma.err;
  }
}

TEST_F(Cli, BlockCompressedCodecsBuildVerifyAndRefuseAlphaInBc1) {
  for (const std::string codec : {"bc1", "bc7"}) {
    const std::string archive_path = work_ + codec + ".tess";
    RunResult built = run({"build", "synthetic:150x90:3:3", "-o", archive_path, "--codec", codec,
                           "--tile", "64", "--border", "1", "-q"});
    ASSERT_EQ(built.exit_code, 0) << codec << ": " << built.err;
    RunResult info = run({"info", archive_path, "--json"});
    ASSERT_EQ(info.exit_code, 0) << info.err;
    EXPECT_EQ(nlohmann::json::parse(info.out)["images"][0]["codec"], codec) << info.out;
    RunResult verified = run({"verify", archive_path});
    EXPECT_EQ(verified.exit_code, 0) << verified.err;
  }
  const std::string refused = work_ + "bc1_alpha.tess";
  RunResult alpha = run({"build", "synthetic:150x90:3:4", "-o", refused, "--codec", "bc1", "-q"});
  EXPECT_EQ(alpha.exit_code, 2) << alpha.err;
  EXPECT_NE(alpha.err.find("cannot be stored with --codec bc1"), std::string::npos) << alpha.err;
  EXPECT_FALSE(std::filesystem::exists(refused));
}

TEST_F(Cli, RenderDrawsTheReferencePictureOfAnOrthographicView) {
  const std::string archive_path = work_ + "r.tess";
  const std::string source = "synthetic:300x200:5:3";
  RunResult built = run({"build", source, "-o", archive_path, "--tile", "64", "--border", "1",
                         "--codec", "png", "--quiet"});
  ASSERT_EQ(built.exit_code, 0) << built.err;
  const Image texels = test::readSource(source);
  ASSERT_EQ(texels.channels, 3u);
  auto archive = Archive::openFile(archive_path);
  ASSERT_TRUE(archive);
  // Expects pixel (px, py) of `picture` to be RGB `rgb` with alpha 255.
  auto expectPixel = [](const Image& picture, uint32_t px, uint32_t py, const uint8_t* rgb,
                        const std::string& what) {
    const uint8_t* got = picture.row(py) + px * 4;
    EXPECT_TRUE(got[0] == rgb[0] && got[1] == rgb[1] && got[2] == rgb[2] && got[3] == 255)
        << what << " pixel (" << px << "," << py << "): got " << int(got[0]) << "," << int(got[1])
        << "," << int(got[2]) << "," << int(got[3]) << " want " << int(rgb[0]) << "," << int(rgb[1])
        << "," << int(rgb[2]);
  };

  // 1 texel per pixel across tile edges (64, 128, 192): texel (110 + px, 70 + py).
  RunResult one = run({"render", archive_path, "--centre", "150,100", "--texels-per-pixel", "1",
                       "--viewport", "80x60", "-o", work_ + "one.png"});
  ASSERT_EQ(one.exit_code, 0) << one.err;
  EXPECT_NE(one.out.find("80x60, level 0 of"), std::string::npos) << one.out;
  Image picture = test::readImagePng(work_ + "one.png");
  ASSERT_EQ(picture.width_px, 80u);
  ASSERT_EQ(picture.height_px, 60u);
  ASSERT_EQ(picture.channels, 4u);
  for (uint32_t py = 0; py < 60; ++py)
    for (uint32_t px = 0; px < 80; ++px)
      expectPixel(picture, px, py, texels.row(70 + py) + (110 + px) * 3, "1 tpp");

  // Over the image's top-left corner: the first 10 columns and rows lie outside.
  RunResult corner = run({"render", archive_path, "--centre", "10,10", "--viewport", "40x40", "-o",
                          work_ + "corner.png"});
  ASSERT_EQ(corner.exit_code, 0) << corner.err;
  picture = test::readImagePng(work_ + "corner.png");
  ASSERT_EQ(picture.channels, 4u);
  for (uint32_t py = 0; py < 40; ++py)
    for (uint32_t px = 0; px < 40; ++px) {
      if (px < 10 || py < 10) {
        const uint8_t* got = picture.row(py) + px * 4;
        EXPECT_TRUE(got[0] == 0 && got[1] == 0 && got[2] == 0 && got[3] == 0)
            << "outside pixel (" << px << "," << py << ") is not transparent black";
      } else {
        expectPixel(picture, px, py, texels.row(py - 10) + (px - 10) * 3, "corner");
      }
    }

  // 2 texels per pixel: level 1 exactly (no blend with level 2), pixel centres on level-1
  // texel centres: u = 100 + 2 (px + 0.5 - 20) = 2 (px + 30) + 1 -> level-1 texel px + 30.
  RunResult two = run({"render", archive_path, "--centre", "100,80", "--texels-per-pixel", "2",
                       "--viewport", "40x30", "-o", work_ + "two.png"});
  ASSERT_EQ(two.exit_code, 0) << two.err;
  EXPECT_NE(two.out.find("level 1 of"), std::string::npos) << two.out;
  picture = test::readImagePng(work_ + "two.png");
  Image level1 = *(*archive)->readRegion(0, 1, {30, 25, 40, 30});
  ASSERT_EQ(level1.channels, 3u);
  for (uint32_t py = 0; py < 30; ++py)
    for (uint32_t px = 0; px < 40; ++px)
      expectPixel(picture, px, py, level1.row(py) + px * 3, "2 tpp");

  // Rotated 90 degrees: u = cx - dy, v = cy + dx, so pixel (px, py) of a 20x20 view centred on
  // (150, 100) shows texel (150 + 10 - py - 1, 100 - 10 + px).
  RunResult rotated = run({"render", archive_path, "--centre", "150,100", "--viewport", "20x20",
                           "--rotation", "90", "-o", work_ + "rot.png"});
  ASSERT_EQ(rotated.exit_code, 0) << rotated.err;
  picture = test::readImagePng(work_ + "rot.png");
  for (uint32_t py = 0; py < 20; ++py)
    for (uint32_t px = 0; px < 20; ++px)
      expectPixel(picture, px, py, texels.row(90 + px) + (159 - py) * 3, "rotated");

  // Bad views are usage errors that write nothing; a missing archive is named.
  const std::string bad_out = work_ + "bad.png";
  for (const std::vector<std::string>& args : std::vector<std::vector<std::string>>{
           {"render", archive_path, "--centre", "1,1", "--viewport", "0x10", "-o", bad_out},
           {"render", archive_path, "--centre", "1,1", "--viewport", "-3x10", "-o", bad_out},
           {"render", archive_path, "--centre", "1,1", "--viewport", "10x", "-o", bad_out},
           {"render", archive_path, "--centre", "1,1", "--texels-per-pixel", "0", "-o", bad_out},
           {"render", archive_path, "--centre", "1", "-o", bad_out},
           {"render", archive_path, "--centre", "1,1", "--image", "1", "-o", bad_out},
       }) {
    RunResult result = run(args);
    EXPECT_EQ(result.exit_code, 2) << args[3] << " " << args[4] << "\n" << result.err;
    EXPECT_FALSE(result.err.empty());
  }
  RunResult missing = run({"render", work_ + "missing.tess", "--centre", "1,1", "-o", bad_out});
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_NE(missing.err.find("missing.tess"), std::string::npos) << missing.err;
  EXPECT_FALSE(std::filesystem::exists(bad_out));
}

TEST_F(Cli, CoverageHintsAreBuiltPrintedVerifiedAndTheirDamageNamed) {
  const std::string path = work_ + "hinted.tess";
  RunResult built = run({"build", "synthetic-scene:60:6:5", "-o", path, "--tile", "64",
                         "--coverage-hints", "--hint-resolution", "8", "--hint-cell", "40"});
  ASSERT_EQ(built.exit_code, 0) << built.err;
  EXPECT_NE(built.out.find("coverage hints:"), std::string::npos) << built.out;
  RunResult info = run({"info", path});
  EXPECT_NE(info.out.find("8 px faces"), std::string::npos) << info.out;
  auto scene = SceneArchive::openFile(path);
  ASSERT_TRUE(scene.has_value());
  auto hints = (*scene)->readCoverageHints();
  ASSERT_TRUE(hints.has_value()) << hints.error().message;
  RunResult verified = run({"verify", path});
  EXPECT_EQ(verified.exit_code, 0) << verified.err;
  EXPECT_NE(verified.out.find(std::to_string(hints->cellCount()) + " coverage hint cells"),
            std::string::npos)
      << verified.out;
  const FileRange range = (*scene)->coverageHintsRange();
  scene->reset();
  std::vector<uint8_t> bytes = test::readFileBytes(path);
  bytes[range.offset_bytes + range.length_bytes - 1] ^= 0x01;
  ASSERT_TRUE(test::writeFileBytes(path, bytes));
  RunResult damaged = run({"verify", path});
  EXPECT_EQ(damaged.exit_code, 3);
  EXPECT_NE(damaged.err.find("coverage hints checksum mismatch"), std::string::npos) << damaged.err;
}

TEST_F(Cli, VerifyWalksTheSceneAndNamesADamagedMesh) {
  const std::string path = work_ + "city.tess";
  RunResult built = run({"build", "synthetic-scene:120:12:5", "-o", path, "--tile", "64", "-q"});
  ASSERT_EQ(built.exit_code, 0) << built.err;
  auto scene = SceneArchive::openFile(path);
  ASSERT_TRUE(scene.has_value()) << scene.error().message;
  RunResult verified = run({"verify", path});
  EXPECT_EQ(verified.exit_code, 0) << verified.err;
  EXPECT_NE(verified.out.find(std::to_string((*scene)->summary().nodes) + " scene nodes"),
            std::string::npos)
      << verified.out;
  // The first mesh blob of the tree: only the scene walk reads it (the 1.0 checks see images).
  SceneMesh mesh;
  auto nodes = (*scene)->allNodes();
  ASSERT_TRUE(nodes.has_value());
  for (const SceneNode& node : *nodes) {
    auto contents = (*scene)->readNode(node);
    ASSERT_TRUE(contents.has_value());
    if (!contents->meshes.empty()) {
      mesh = contents->meshes[0];
      break;
    }
  }
  ASSERT_GT(mesh.blob.length_bytes, 0u);
  scene->reset();
  std::vector<uint8_t> bytes = test::readFileBytes(path);
  bytes[mesh.blob.offset_bytes + mesh.blob.length_bytes / 2] ^= 0x10;
  ASSERT_TRUE(test::writeFileBytes(path, bytes));
  RunResult damaged = run({"verify", path});
  EXPECT_EQ(damaged.exit_code, 3);
  EXPECT_NE(damaged.err.find("mesh " + std::to_string(mesh.index)), std::string::npos)
      << damaged.err;
  EXPECT_NE(damaged.out.find("1 fault"), std::string::npos) << damaged.out;
}

TEST_F(Cli, VerifyOfATruncatedArchiveExitsThree) {
  const std::string path = work_ + "t.tess";
  ASSERT_EQ(run({"build", "synthetic:100x100", "-o", path, "--codec", "lz4", "-q"}).exit_code, 0);
  std::vector<uint8_t> bytes = test::readFileBytes(path);
  bytes.resize(bytes.size() - 1);
  ASSERT_TRUE(test::writeFileBytes(path, bytes));
  RunResult result = run({"verify", path});
  EXPECT_EQ(result.exit_code, 3);
  EXPECT_NE(result.err.find(path), std::string::npos) << result.err;
}

TEST_F(Cli, HelpOnEverySubcommandExitsZero) {
  for (std::vector<std::string> args : {std::vector<std::string>{"--help"},
                                        {"build", "--help"},
                                        {"info", "--help"},
                                        {"verify", "--help"},
                                        {"extract", "--help"},
                                        {"render", "--help"},
                                        {"view", "--help"}}) {
    RunResult result = run(args);
    EXPECT_EQ(result.exit_code, 0) << args[0];
    EXPECT_NE(result.out.find("Usage"), std::string::npos) << result.out;
  }
}

TEST_F(Cli, UsageErrorsExitTwo) {
  const std::string out = work_ + "u.tess";
  const std::vector<std::vector<std::string>> cases = {
      {},
      {"frobnicate"},
      {"build", "synthetic:10x10"},
      {"build", "synthetic:10x10", "-o", out, "--no-such-flag"},
      {"build", "synthetic:10x10", "-o", out, "--codec", "gif"},
      {"build", "synthetic:10x10", "-o", out, "--order", "spiral"},
      {"build", "synthetic:10x10", "-o", out, "--tile", "abc"},
      {"build", "synthetic:10x10", "-o", out, "--chroma", "411"},
      {"info"},
      {"extract", out, "-o", work_ + "x.png"},
      {"extract", out, "-o", work_ + "x.png", "--tile", "1"},
      {"view"},
      {"view", out, "--renderer", "bogus"},
  };
  for (const auto& args : cases) {
    RunResult result = run(args);
    std::string joined;
    for (const auto& arg : args) joined += arg + " ";
    EXPECT_EQ(result.exit_code, 2) << joined << "\n" << result.err;
    EXPECT_FALSE(result.err.empty()) << joined;
  }
  EXPECT_TRUE(listDir(work_).empty());
}

TEST_F(Cli, FlyRecordsEveryFrameAndTimesEachJump) {
  const std::string archive = work_ + "fly.tess";
  ASSERT_EQ(
      run({"build", "synthetic:4096x2048:2:3", "-o", archive, "--tile", "128", "-q"}).exit_code, 0);
  // Two spots 0.5 s each, 30 fps: a start and one jump (the second keyframe pair).
  const std::string path_file = work_ + "jumps.path";
  std::ofstream(path_file) << "# t_s x y texels_per_pixel [rotation jump]\n"
                              "0 600 600 1\n0.49 600 600 1\n0.5 3500 1500 1 0 jump\n"
                              "1.0 3500 1500 1\n";
  const std::string out = work_ + "fly-out";
  // Niceness, not SCHED_IDLE, for the loaders: ctest runs other tests beside this one, and
  // idle-priority loaders would wait for them (docs/runtime.md), leaving jumps unloaded.
  RunResult flown =
      run({"fly", archive, "--path", path_file, "--fps", "30", "--viewport", "320x240",
           "--cache-mib", "64", "--decode-bound", "--loader-priority", "nice", "-q", "--out", out});
  ASSERT_EQ(flown.exit_code, 0) << flown.err;
  nlohmann::json summary = nlohmann::json::parse(slurp(out + "/summary.json"));
  std::istringstream csv(slurp(out + "/frames.csv"));
  std::string line;
  size_t csv_frames = 0;
  std::getline(csv, line);  // header
  while (std::getline(csv, line)) csv_frames += !line.empty();
  EXPECT_EQ(summary["frames"].get<size_t>(), csv_frames);
  EXPECT_EQ(csv_frames, 31u);  // t = 0, 1/30, ..., 1.0
  ASSERT_EQ(summary["jumps"].size(), 2u);
  for (const auto& jump : summary["jumps"]) {
    ASSERT_FALSE(jump["clip_region_ms"].is_null()) << jump.dump();
    EXPECT_GE(jump["clip_region_ms"].get<double>(), 0);
    EXPECT_GT(jump["tiles_uploaded"].get<size_t>(), 0u);
    EXPECT_GT(jump["decode_bound_ms"].get<double>(), 0);
  }
  EXPECT_EQ(summary["frames_fully_covered_pct"].get<double>(), 100.0);
  EXPECT_GE(summary["read_amplification"].get<double>(), 1.0);
  EXPECT_GT(summary["tiles_loaded"].get<uint64_t>(), 0u);
  EXPECT_EQ(summary["load_failures"].get<uint64_t>(), 0u);

  // Rendered headless (EGL on llvmpipe in CI): GPU and render-thread times, pictures at rest
  // against the CPU reference, screenshots and the self-contained report.
  const std::string bordered = work_ + "fly-b1.tess";
  ASSERT_EQ(run({"build", "synthetic:4096x2048:2:3", "-o", bordered, "--tile", "128", "--border",
                 "1", "--codec", "png", "-q"})
                .exit_code,
            0);
  for (const std::string renderer : {"tile-quads", "clipmap"}) {
    SCOPED_TRACE(renderer);
    const std::string rendered = work_ + "fly-" + renderer;
    RunResult drawn =
        run({"fly", bordered, "--path", path_file, "--fps", "30", "--viewport", "160x120",
             "--render", renderer, "--screenshots", "3,20", "--report", "-q", "--out", rendered});
    ASSERT_EQ(drawn.exit_code, 0) << drawn.err;
    nlohmann::json s = nlohmann::json::parse(slurp(rendered + "/summary.json"));
    EXPECT_EQ(s["renderer"], renderer);
    EXPECT_GT(s["render_ms"]["p50"].get<double>(), 0);
    EXPECT_GT(s["gpu_ms"]["max"].get<double>(), 0);
    // Storage was allocated before the flight's clock started, and no frame allocated more.
    EXPECT_GT(s["render_setup_ms"].get<double>(), 0);
    EXPECT_EQ(s["render_storage_allocations"].get<uint32_t>(), 0u);
    EXPECT_LE(s["replanned_frames"].get<size_t>(), s["frames"].get<size_t>());
    for (const auto& jump : s["jumps"]) EXPECT_GE(jump["rest_psnr_db"].get<double>(), 45.0);
    for (const char* file : {"frame-3.png", "frame-20.png", "rest-0.png", "rest-1.png",
                             "rest-1-levels.png", "report.html"})
      EXPECT_TRUE(std::filesystem::exists(rendered + "/" + file)) << file;
    const std::string html = slurp(rendered + "/report.html");
    EXPECT_NE(html.find("<svg"), std::string::npos);
    EXPECT_NE(html.find("data:image/png;base64,iVBORw0KGgo"), std::string::npos);  // a PNG
    EXPECT_EQ(html.find("http"), html.find("http://www.w3.org/2000/svg"))
        << "the report fetches nothing";
  }
  RunResult bogus = run({"fly", bordered, "--render", "vulkan", "-q", "--out", out});
  EXPECT_EQ(bogus.exit_code, 2);

  // A path file with a bad line fails naming the file; no archive fails naming it.
  std::ofstream(work_ + "bad.path") << "0 600 600 1\n0.5 six hundred 600 1\n";
  RunResult bad_path = run({"fly", archive, "--path", work_ + "bad.path", "-q", "--out", out});
  EXPECT_EQ(bad_path.exit_code, 2);  // an invalid argument, like a bad --path name
  EXPECT_NE(bad_path.err.find("bad.path"), std::string::npos) << bad_path.err;
  RunResult missing = run({"fly", work_ + "none.tess", "-q", "--out", out});
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_NE(missing.err.find("none.tess"), std::string::npos) << missing.err;
}

TEST_F(Cli, FlyOverASimulatedLinkReportsTheLinkAndTheScheduler) {
  const std::string archive = work_ + "link.tess";
  ASSERT_EQ(
      run({"build", "synthetic:4096x2048:2:3", "-o", archive, "--tile", "128", "-q"}).exit_code, 0);
  const std::string path_file = work_ + "link.path";
  std::ofstream(path_file) << "0 600 600 1\n0.49 600 600 1\n0.5 3500 1500 1 0 jump\n"
                              "1.0 3500 1500 1\n";
  // A column of frames.csv by name, every row.
  auto column = [&](const std::string& dir, const std::string& name) {
    std::istringstream csv(slurp(dir + "/frames.csv"));
    std::string line, cell;
    std::getline(csv, line);
    std::istringstream header(line);
    size_t index = 0, found = SIZE_MAX;
    for (; std::getline(header, cell, ','); ++index)
      if (cell == name) found = index;
    EXPECT_NE(found, SIZE_MAX) << name;
    std::vector<double> values;
    while (std::getline(csv, line)) {
      std::istringstream row(line);
      for (size_t i = 0; std::getline(row, cell, ','); ++i)
        if (i == found) values.push_back(std::stod(cell));
    }
    return values;
  };
  for (const std::string adaptive : {"auto", "off"}) {
    SCOPED_TRACE(adaptive);
    const std::string out = work_ + "link-" + adaptive;
    RunResult flown = run({"fly", archive, "--path", path_file, "--fps", "30", "--viewport",
                           "320x240", "--link", "50mbit:5ms", "--adaptive", adaptive,
                           "--loader-priority", "nice", "-q", "--out", out});
    ASSERT_EQ(flown.exit_code, 0) << flown.err;
    nlohmann::json s = nlohmann::json::parse(slurp(out + "/summary.json"));
    EXPECT_EQ(s["simulated_link"], "50mbit:5ms");
    EXPECT_EQ(s["adaptive"], adaptive == "auto" ? "on" : "off");
    // The egress report: beyond the views at most half their bytes again (the default).
    if (adaptive == "auto") {
      const nlohmann::json& egress = s["egress"];
      EXPECT_EQ(egress["budget"], "default");
      EXPECT_GT(egress["view_bytes"].get<uint64_t>(), 0u);
      EXPECT_LE(2 * egress["beyond_view_bytes"].get<uint64_t>(),
                egress["view_bytes"].get<uint64_t>());
      EXPECT_EQ(egress["requests"], s["link"]["requests"]);
    } else {
      EXPECT_FALSE(s.contains("egress"));
    }
    // Every byte the loader read crossed the link (the header and directory pages too).
    EXPECT_GT(s["bytes_read"].get<uint64_t>(), 0u);
    EXPECT_GE(s["link"]["bytes_received"].get<uint64_t>(), s["bytes_read"].get<uint64_t>());
    EXPECT_GT(s["link"]["requests"].get<uint64_t>(), 0u);
    // Opening read the header across the link: at least its round trip.
    EXPECT_GE(s["open_ms"].get<double>(), 5.0);
    EXPECT_GT(s["link_bytes_per_s"].get<double>(), 0);
    // A 50 Mbit/s link delivers no more than 6.25 MB/s, whatever the estimate's window.
    EXPECT_LT(s["link_bytes_per_s"].get<double>(), 6.25e6 * 1.01);
    const std::vector<double> flags = column(out, "adaptive");
    ASSERT_EQ(flags.size(), s["frames"].get<size_t>());
    for (double flag : flags) EXPECT_EQ(flag, adaptive == "auto" ? 1 : 0);
    const std::vector<double> levels = column(out, "requested_level");
    const std::vector<double> desired = column(out, "desired_level");
    ASSERT_EQ(levels.size(), desired.size());
    for (size_t i = 0; i < levels.size(); ++i) EXPECT_GE(levels[i], desired[i]);
  }
  RunResult bad = run({"fly", archive, "--link", "20mbit", "-q", "--out", work_ + "link-bad"});
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("'20mbit'"), std::string::npos) << bad.err;
}

// The same commands on a URL: nginx serves the archive statically; every subcommand reads it
// through the HTTP source and must see what it sees in the local file.
TEST_F(Cli, InfoVerifyExtractAndFlyReadAnArchiveOverHttp) {
  if (!test::NginxServer::available())
    GTEST_SKIP() << test::NginxServer::kBinary
                 << " is not installed (scripts/install-deps.sh installs nginx-light)";
  std::filesystem::create_directories(work_ + "www");
  const std::string archive = work_ + "www/remote.tess";
  ASSERT_EQ(
      run({"build", "synthetic:4096x2048:2:3", "-o", archive, "--tile", "128", "-q"}).exit_code, 0);
  auto nginx = test::NginxServer::start(work_ + "www", work_ + "nginx");
  ASSERT_TRUE(nginx) << nginx.error().message;
  const std::string url = (*nginx)->url("remote.tess");

  RunResult local_info = run({"info", archive, "--json"});
  RunResult remote_info = run({"info", url, "--json"});
  ASSERT_EQ(remote_info.exit_code, 0) << remote_info.err;
  nlohmann::json local = nlohmann::json::parse(local_info.out);
  nlohmann::json remote = nlohmann::json::parse(remote_info.out);
  EXPECT_EQ(remote["path"], url);
  EXPECT_EQ(remote["images"], local["images"]);  // level tables included: every directory page
  EXPECT_EQ(remote["file_bytes"], local["file_bytes"]);

  RunResult verified = run({"verify", url});
  EXPECT_EQ(verified.exit_code, 0) << verified.err;
  for (const std::string& source : {archive, url}) {
    RunResult extracted = run({"extract", source, "--level", "1", "--rect", "100,50,300,200", "-o",
                               work_ + (source == url ? "remote.png" : "local.png")});
    ASSERT_EQ(extracted.exit_code, 0) << extracted.err;
  }
  EXPECT_EQ(slurp(work_ + "remote.png"), slurp(work_ + "local.png"));

  const std::string out = work_ + "fly-remote";
  RunResult flown =
      run({"fly", url, "--duration", "1", "--path", "pan", "--speed", "2000", "--fps", "30",
           "--viewport", "320x240", "--loader-priority", "nice", "-q", "--out", out});
  ASSERT_EQ(flown.exit_code, 0) << flown.err;
  nlohmann::json summary = nlohmann::json::parse(slurp(out + "/summary.json"));
  EXPECT_EQ(summary["archive"], url);
  // The remote tuning (tuneForRemoteSource): a batch is one read, many reads in flight, no
  // fetch-ahead, adaptive scheduling.
  EXPECT_EQ(summary["merge_gap_bytes"], 16 * 1024);
  EXPECT_EQ(summary["batch_gap_bytes"], 16 * 1024);
  EXPECT_GE(summary["loader_threads"].get<uint32_t>(), kRemoteLoaderThreads);
  EXPECT_EQ(summary["read_ahead_bytes"], 0);
  EXPECT_EQ(summary["adaptive"], "on");
  EXPECT_GT(summary["tiles_loaded"].get<uint64_t>(), 0u);
  EXPECT_EQ(summary["load_failures"].get<uint64_t>(), 0u);
  ASSERT_TRUE(summary.contains("link")) << summary.dump();
  EXPECT_GT(summary["link"]["requests"].get<uint64_t>(), 1u);
  EXPECT_EQ(summary["link"]["errors"].get<uint64_t>(), 0u);
  EXPECT_GT(summary["link"]["bytes_received"].get<uint64_t>(), 0u);
  // A local flight keeps the disk defaults.
  RunResult local_fly = run({"fly", archive, "--duration", "0.2", "--fps", "10", "--viewport",
                             "320x240", "-q", "--out", out});
  ASSERT_EQ(local_fly.exit_code, 0) << local_fly.err;
  nlohmann::json local_summary = nlohmann::json::parse(slurp(out + "/summary.json"));
  const StreamerOptions defaults;
  EXPECT_EQ(local_summary["merge_gap_bytes"], defaults.merge_gap_bytes);
  EXPECT_EQ(local_summary["batch_gap_bytes"], defaults.batch_gap_bytes);
  EXPECT_EQ(local_summary["read_ahead_bytes"], defaults.read_ahead_bytes);
  EXPECT_EQ(local_summary["adaptive"], "off");

  RunResult missing = run({"info", (*nginx)->url("missing.tess")});
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_NE(missing.err.find("missing.tess: bytes=0-16383: HTTP 404"), std::string::npos)
      << missing.err;
  RunResult no_ranges = run({"info", (*nginx)->url("noranges/remote.tess")});
  EXPECT_EQ(no_ranges.exit_code, 1);
  EXPECT_NE(no_ranges.err.find("server does not honour byte ranges"), std::string::npos)
      << no_ranges.err;
}

TEST_F(Cli, DemoBuildsOnceFliesTheStandardPathsAndLinksTheirReports) {
  const std::string dir = work_ + "demo";
  RunResult first =
      run({"demo", "--dir", dir, "--size", "2048x1024", "--seconds", "1", "--viewport", "160x120"});
  ASSERT_EQ(first.exit_code, 0) << first.err;
  EXPECT_NE(first.out.find("building"), std::string::npos);
  EXPECT_NE(first.out.find(dir + "/demo.html"), std::string::npos) << first.out;
  const std::string index = slurp(dir + "/demo.html");
  for (const char* path : {"jump", "pan", "zoom"}) {
    EXPECT_NE(index.find(fmt::format("demo/{}/report.html", path)), std::string::npos) << path;
    EXPECT_TRUE(std::filesystem::exists(dir + "/demo/" + path + "/report.html")) << path;
    nlohmann::json s = nlohmann::json::parse(slurp(dir + "/demo/" + path + "/summary.json"));
    EXPECT_EQ(s["frames_fully_covered_pct"].get<double>(), 100.0) << path;
  }
  RunResult second = run(
      {"demo", "--dir", dir, "--size", "2048x1024", "--seconds", "0.5", "--viewport", "160x120"});
  ASSERT_EQ(second.exit_code, 0) << second.err;
  EXPECT_NE(second.out.find("up to date"), std::string::npos) << second.out;
}

TEST_F(Cli, BadInputsFailNamingTheFileAndLeaveNoOutput) {
  const std::string inputs = dir_ + "in/";
  std::filesystem::create_directories(inputs);
  ASSERT_TRUE(test::writeFileBytes(inputs + "empty.png", {}));
  ASSERT_TRUE(test::writeFileBytes(inputs + "absurd.tif",
                                   test::makeRawTiffHeader(4000000000u, 4000000000u, 16)));
  ASSERT_TRUE(test::writeFileBytes(inputs + "absurd.png",
                                   test::makePngHeaderOnly(4000000000u, 4000000000u)));
  std::vector<uint8_t> pixels = test::makeTestPixels(64, 48, 3, 1);
  test::JpegSpec jpeg;
  jpeg.width_px = 64;
  jpeg.height_px = 48;
  ASSERT_EQ(test::writeJpeg(inputs + "good.jpg", jpeg, pixels), "");
  std::vector<uint8_t> jpeg_bytes = test::readFileBytes(inputs + "good.jpg");
  jpeg_bytes.resize(jpeg_bytes.size() / 2);
  ASSERT_TRUE(test::writeFileBytes(inputs + "truncated.jpg", jpeg_bytes));
  // 16-bit PNG builds (with a codec that holds it); signed samples are still refused.
  test::TiffSpec signed16;
  signed16.width_px = 64;
  signed16.height_px = 48;
  signed16.bits = 16;
  signed16.sample_format = 2;  // SAMPLEFORMAT_INT
  ASSERT_EQ(test::writeTiff(inputs + "signed.tif", signed16, pixels), "");
  for (const std::string name :
       {"missing.png", "empty.png", "absurd.tif", "absurd.png", "truncated.jpg", "signed.tif"}) {
    RunResult result = run({"build", inputs + name, "-o", work_ + "out.tess", "--threads", "2"});
    EXPECT_NE(result.exit_code, 0) << name;
    EXPECT_NE(result.exit_code, 2) << name << ": a bad input is not a usage error";
    EXPECT_NE(result.err.find(inputs + name), std::string::npos) << result.err;
    EXPECT_TRUE(listDir(work_).empty()) << name;
  }
}

TEST_F(Cli, AnUnwritableOutputFailsAndKeepsThePreviousFile) {
  ASSERT_TRUE(test::writeFileBytes(work_ + "file", {7}));
  RunResult under_file = run({"build", "synthetic:64x64", "-o", work_ + "file/out.tess", "-q"});
  EXPECT_EQ(under_file.exit_code, 1);
  EXPECT_NE(under_file.err.find(work_ + "file/out.tess"), std::string::npos) << under_file.err;
  EXPECT_EQ(listDir(work_), std::vector<std::string>{"file"});
  EXPECT_EQ(test::readFileBytes(work_ + "file"), std::vector<uint8_t>{7});
}

TEST_F(Cli, BuildJsonReportsWhatWasWritten) {
  RunResult built = run({"build", "synthetic:200x150:2:3", "-o", work_ + "j.tess", "--tile", "64",
                         "--codec", "lz4", "--json"});
  ASSERT_EQ(built.exit_code, 0) << built.err;
  nlohmann::json json = nlohmann::json::parse(built.out, nullptr, false);
  ASSERT_FALSE(json.is_discarded()) << built.out;
  EXPECT_EQ(json["output_bytes"].get<uint64_t>(), std::filesystem::file_size(work_ + "j.tess"));
  uint64_t tiles = json["tiles_encoded"].get<uint64_t>() + json["tiles_uniform"].get<uint64_t>() +
                   json["tiles_empty"].get<uint64_t>();
  EXPECT_EQ(tiles, 4u * 3 + 2 * 2 + 1);         // 200x150, 100x75, 50x38
  EXPECT_TRUE(built.err.empty()) << built.err;  // no progress bar when not a terminal
}

TEST_F(Cli, InfoAndVerifyOfANonArchiveFail) {
  ASSERT_TRUE(test::writeFileBytes(work_ + "junk.tess", std::vector<uint8_t>(20000, 'j')));
  RunResult info = run({"info", work_ + "junk.tess"});
  EXPECT_EQ(info.exit_code, 1);
  EXPECT_NE(info.err.find("bad magic"), std::string::npos) << info.err;
  RunResult verify = run({"verify", work_ + "junk.tess"});
  EXPECT_EQ(verify.exit_code, 3);
  RunResult missing = run({"info", work_ + "missing.tess"});
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_NE(missing.err.find(work_ + "missing.tess"), std::string::npos) << missing.err;
}

TEST_F(Cli, ViewWithoutADisplayExitsOnePointingToFly) {
  const std::string archive = work_ + "v.tess";
  ASSERT_EQ(run({"build", "synthetic:300x200", "-o", archive, "--tile", "64", "-q"}).exit_code, 0);
  const std::vector<std::string> env = environmentWithoutDisplay();
  RunResult result = runTessera({"view", archive}, logs_, &env);
  EXPECT_EQ(result.exit_code, 1) << result.err;
  EXPECT_NE(result.err.find("no display"), std::string::npos) << result.err;
  EXPECT_NE(result.err.find("tessera fly"), std::string::npos) << result.err;
}

TEST_F(Cli, ViewBadArgumentsAreUsageErrorsAndAMissingArchiveIsNamed) {
  const std::string archive = work_ + "v.tess";
  ASSERT_EQ(run({"build", "synthetic:300x200", "-o", archive, "--tile", "64", "-q"}).exit_code, 0);
  const std::vector<std::string> env = environmentWithoutDisplay();
  RunResult bogus = runTessera({"view", archive, "--renderer", "bogus"}, logs_, &env);
  EXPECT_EQ(bogus.exit_code, 2) << bogus.err;
  EXPECT_NE(bogus.err.find("bogus"), std::string::npos) << bogus.err;
  RunResult size = runTessera({"view", archive, "--size", "wide"}, logs_, &env);
  EXPECT_EQ(size.exit_code, 2) << size.err;
  RunResult image = runTessera({"view", archive, "--image", "3"}, logs_, &env);
  EXPECT_EQ(image.exit_code, 2) << image.err;
  EXPECT_NE(image.err.find("no image 3"), std::string::npos) << image.err;

  const std::string missing = work_ + "missing.tess";
  RunResult gone = runTessera({"view", missing}, logs_, &env);
  EXPECT_EQ(gone.exit_code, 1) << gone.err;
  EXPECT_NE(gone.err.find(missing), std::string::npos) << gone.err;
}

// The real window on a virtual X server: only where xvfb-run is installed (CI need not have
// it). Mesa's llvmpipe gives the OpenGL 4.5 core context.
TEST_F(Cli, ViewUnderXvfbDrawsFramesAndWritesAScreenshot) {
  const std::string xvfb_run = findOnPath("xvfb-run");
  if (xvfb_run.empty()) GTEST_SKIP() << "xvfb-run is not installed (apt-get install xvfb)";
  const std::string archive = work_ + "v.tess";
  ASSERT_EQ(run({"build", "synthetic:1000x700", "-o", archive, "--tile", "64", "-q"}).exit_code, 0);
  // Each window runs as `env ASAN_OPTIONS=...:detect_leaks=0 tessera view` (support/sanitizers.h).
  const std::string no_leak_check = test::asanOptionsWithoutLeakCheck();
  for (const char* renderer : {"tile-quads", "clipmap"}) {
    const std::string shots = work_ + renderer;
    std::filesystem::create_directories(shots);
    RunResult result =
        runProgram(xvfb_run,
                   {"-a", "-s", "-screen 0 1024x768x24", "env", no_leak_check, TESSERA_CLI_PATH,
                    "view", archive, "--renderer", renderer, "--size", "320x240", "--frames", "30",
                    "--screenshot-dir", shots},
                   logs_);
    ASSERT_EQ(result.exit_code, 0) << renderer << ": " << result.err;
    const std::string shot = shots + "/tessera-screenshot-1.png";
    ASSERT_TRUE(std::filesystem::exists(shot)) << renderer << ": " << result.err;
    const std::string png = slurp(shot);
    ASSERT_GT(png.size(), 8u);
    EXPECT_EQ(png.substr(1, 3), "PNG");
    // The window's framebuffer is the --size one; the picture shows the (not flat) image.
    Image picture(320, 240, 4);
    ASSERT_TRUE(detail::decodeTile(
        Codec::kPng, {reinterpret_cast<const uint8_t*>(png.data()), png.size()}, picture))
        << renderer;
    std::set<uint32_t> colours;
    for (uint32_t y = 0; y < picture.height_px; y += 8)
      for (uint32_t x = 0; x < picture.width_px; x += 8) {
        const uint8_t* p = picture.row(y) + x * 4;
        colours.insert(p[0] | p[1] << 8 | p[2] << 16);
      }
    EXPECT_GT(colours.size(), 20u) << renderer << ": the screenshot is nearly blank";

    // The same view with every overlay on (screenshots include them), and the fly-over.
    const std::string overlaid = work_ + renderer + "-overlays";
    std::filesystem::create_directories(overlaid);
    RunResult with_overlays =
        runProgram(xvfb_run,
                   {"-a", "-s", "-screen 0 1024x768x24", "env", no_leak_check, TESSERA_CLI_PATH,
                    "view", archive, "--renderer", renderer, "--size", "320x240", "--frames", "30",
                    "--overlays", "levels,clip,grid", "--screenshot-dir", overlaid},
                   logs_);
    ASSERT_EQ(with_overlays.exit_code, 0) << with_overlays.err;
    const std::string tinted = slurp(overlaid + "/tessera-screenshot-1.png");
    Image overlay_picture(320, 240, 4);
    ASSERT_TRUE(detail::decodeTile(Codec::kPng,
                                   {reinterpret_cast<const uint8_t*>(tinted.data()), tinted.size()},
                                   overlay_picture));
    size_t changed = 0;
    for (size_t i = 0; i < picture.texels.size(); i += 4)
      changed += std::abs(int(picture.texels[i]) - int(overlay_picture.texels[i])) > 8 ||
                 std::abs(int(picture.texels[i + 2]) - int(overlay_picture.texels[i + 2])) > 8;
    EXPECT_GT(changed, picture.texels.size() / 4 / 4) << renderer << ": overlays not drawn";
    RunResult fly_over =
        runProgram(xvfb_run,
                   {"-a", "-s", "-screen 0 1024x768x24", "env", no_leak_check, TESSERA_CLI_PATH,
                    "view", archive, "--renderer", renderer, "--size", "320x240", "--frames", "20",
                    "--perspective", "--screenshot-dir", overlaid},
                   logs_);
    EXPECT_EQ(fly_over.exit_code, 0) << fly_over.err;
    EXPECT_TRUE(std::filesystem::exists(overlaid + "/tessera-screenshot-2.png"));
  }
}

}  // namespace
}  // namespace tessera
