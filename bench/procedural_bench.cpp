// tessera-procedural-bench: the figures of docs/procedural.md, "Figures".
//   setup DB --images DIR --size WxH --count N [--seed S]   brushes cut from real pictures
//                                                           (bench/procedural_data.sh fetches
//                                                           them) and a generated instance set
//   composite --images DIR [--seconds S] [--gpu]            tiles/s per core at 10, 100 and
//                                                           1000 instances per tile, beside
//                                                           JPEG decode of the same tiles;
//                                                           --gpu adds the GPU compositor on
//                                                           a headless context (llvmpipe
//                                                           here: a CPU, all of its cores)
//   query DB [--tiles N] [--level L]                        spatial query time per tile
// DB is an SQLite file or a PostGIS connection string.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include <fmt/format.h>

#include <tessera/brushes.h>
#include <tessera/gl.h>
#include <tessera/procedural.h>
#include <tessera/procedural_build.h>

#include "analysis/tile_analysis.h"
#include "codecs/decode.h"
#include "codecs/encode.h"

namespace tessera {
namespace {

using Clock = std::chrono::steady_clock;

[[noreturn]] void die(const std::string& message) {
  std::fprintf(stderr, "tessera-procedural-bench: %s\n", message.c_str());
  std::exit(1);
}

template <typename T>
T check(Result<T> result) {
  if (!result) die(result.error().message);
  return std::move(*result);
}
void check(Result<void> result) {
  if (!result) die(result.error().message);
}

std::string argument(int argc, char** argv, const char* name, const char* fallback) {
  for (int i = 2; i + 1 < argc; ++i)
    if (std::strcmp(argv[i], name) == 0) return argv[i + 1];
  if (!fallback) die(fmt::format("missing {}", name));
  return fallback;
}

// A square cut from the picture's centre, resampled to `side` by box averaging, with alpha
// falling off over the outer quarter of a disc (or opaque everywhere for `square`).
Image cutBrush(const Image& picture, uint32_t side, bool square) {
  const uint32_t source = std::min(picture.width_px, picture.height_px);
  const uint32_t x0 = (picture.width_px - source) / 2, y0 = (picture.height_px - source) / 2;
  Image brush(side, side, 4);
  for (uint32_t y = 0; y < side; ++y) {
    for (uint32_t x = 0; x < side; ++x) {
      uint32_t sx0 = x0 + x * source / side, sx1 = std::max(sx0 + 1, x0 + (x + 1) * source / side);
      uint32_t sy0 = y0 + y * source / side, sy1 = std::max(sy0 + 1, y0 + (y + 1) * source / side);
      uint32_t sum[3] = {0, 0, 0}, n = 0;
      for (uint32_t sy = sy0; sy < sy1; ++sy)
        for (uint32_t sx = sx0; sx < sx1; ++sx, ++n)
          for (int c = 0; c < 3; ++c)
            sum[c] += picture.texels[(size_t(sy) * picture.width_px + sx) * 4 + c];
      uint8_t* t = &brush.texels[(size_t(y) * side + x) * 4];
      for (int c = 0; c < 3; ++c) t[c] = uint8_t(sum[c] / n);
      double d = std::hypot(x + 0.5 - side / 2.0, y + 0.5 - side / 2.0) / (side / 2.0);
      t[3] = square ? 255 : uint8_t(std::clamp((1 - d) * 4, 0.0, 1.0) * 255);
    }
  }
  return brush;
}

std::vector<Brush> realBrushes(const std::string& dir) {
  auto load = [&](const char* name) { return check(readImageRgba(dir + "/" + name, "/tmp")); };
  const Image grass = load("grass.png"), gravel = load("gravel.png"), brick = load("brick.png"),
              coffee = load("coffee.png"), chelsea = load("chelsea.png");
  auto brush = [](const char* name, BlendMode mode, std::vector<Image> images) {
    Brush b;
    b.name = name;
    b.blend = mode;
    b.images = std::move(images);
    return b;
  };
  return {brush("meadow", BlendMode::kNormal, {cutBrush(grass, 256, true)}),
          brush("gravel", BlendMode::kNormal,
                {cutBrush(gravel, 128, false), cutBrush(gravel, 96, false)}),
          brush("brick", BlendMode::kMultiply, {cutBrush(brick, 96, false)}),
          brush("pebbles", BlendMode::kNormal, {cutBrush(coffee, 64, false)}),
          brush("moss", BlendMode::kOverlay, {cutBrush(grass, 64, false)}),
          brush("glint", BlendMode::kAdd, {cutBrush(chelsea, 32, false)})};
}

int runSetup(int argc, char** argv) {
  const std::string db_name = argv[2];
  uint32_t w = 0, h = 0;
  if (std::sscanf(argument(argc, argv, "--size", nullptr).c_str(), "%ux%u", &w, &h) != 2)
    die("--size WxH");
  const uint64_t count = std::stoull(argument(argc, argv, "--count", nullptr));
  const uint64_t seed = std::stoull(argument(argc, argv, "--seed", "1"));
  auto db = check(openBrushDatabase(db_name, true));
  check(db->setTextureExtent({w, h}));
  const std::vector<Brush> brushes = realBrushes(argument(argc, argv, "--images", nullptr));
  for (const Brush& brush : brushes) check(db->addBrush(brush));
  const auto start = Clock::now();
  std::vector<BrushInstance> all = generateInstances(count, {w, h}, uint32_t(brushes.size()), seed);
  for (size_t first = 0; first < all.size(); first += 1000000) {
    size_t n = std::min<size_t>(1000000, all.size() - first);
    check(db->addInstances({all.data() + first, n}));
  }
  std::printf("%s: %llu instances in %.1f s\n", db_name.c_str(), (unsigned long long)count,
              std::chrono::duration<double>(Clock::now() - start).count());
  return 0;
}

// Three overlapping opaque base instances over the whole tile (the generated sets cover every
// point with about four) and n - 3 detail stamps inside it, sizes as the generator draws them:
// a typical tile of the generated sets.
std::vector<BrushInstance> tileInstances(uint32_t n, uint32_t brush_count, std::mt19937_64& rng) {
  std::vector<BrushInstance> instances;
  for (uint32_t b = 0; b < 3; ++b) {
    BrushInstance base;
    base.brush = 0;
    base.x_px = 40.0 + 90 * b;
    base.y_px = 200.0 - 70 * b;
    base.radius_px = 300;
    base.rotation_rad = 0.3f + b;
    base.id = b + 1;
    instances.push_back(base);
  }
  std::uniform_real_distribution<double> unit(0, 1);
  for (uint32_t i = 3; i < n; ++i) {
    BrushInstance detail;
    detail.id = i + 1;
    detail.brush = 1 + uint32_t(rng() % (brush_count - 1));
    detail.x_px = unit(rng) * 256;
    detail.y_px = unit(rng) * 256;
    double size = unit(rng);
    detail.radius_px = float(1 + size * size * 48);
    detail.rotation_rad = float(unit(rng) * 6.28);
    detail.scale = float(0.75 + unit(rng) * 0.5);
    detail.variant = uint8_t(rng());
    detail.layer = 2;
    instances.push_back(detail);
  }
  return instances;
}

bool hasFlag(int argc, char** argv, const char* name) {
  for (int i = 2; i < argc; ++i)
    if (std::strcmp(argv[i], name) == 0) return true;
  return false;
}

/// Tiles per second of `composite` over `seconds`, cycling through `count` tiles.
template <typename Composite>
double rate(double seconds, size_t count, Composite composite) {
  uint64_t done = 0;
  const auto start = Clock::now();
  while (std::chrono::duration<double>(Clock::now() - start).count() < seconds) {
    composite(done % count);
    ++done;
  }
  return done / std::chrono::duration<double>(Clock::now() - start).count();
}

/// The GPU compositor on the same tiles, raw and as paged, and the largest difference from
/// the CPU compositor over them.
void runGpuComposite(GpuCompositor& gpu, uint32_t n, double seconds,
                     const std::vector<std::vector<BrushInstance>>& tiles,
                     const std::vector<detail::TileAnalysis>& analysed, double decode_rate) {
  const TileGeometry geometry{0, 0, 0, 256, 0, 256, 256};
  Image out, cpu;
  uint32_t max_difference = 0;
  for (const auto& instances : tiles) {
    check(gpu.compositeTile(geometry, instances, out));
    check(compositeTile(gpu.brushSet(), geometry, instances, cpu));
    for (size_t i = 0; i < out.texels.size(); ++i)
      max_difference =
          std::max<uint32_t>(max_difference, uint32_t(std::abs(out.texels[i] - cpu.texels[i])));
  }
  const double raw = rate(seconds, tiles.size(),
                          [&](size_t t) { check(gpu.compositeTile(geometry, tiles[t], out)); });
  const double paged = rate(seconds, analysed.size(), [&](size_t t) {
    check(gpu.compositeTile(geometry, analysed[t].kept, out, analysed[t].clips));
  });
  std::printf(
      "%-10u GPU: %8.1f tiles/s raw (%5.1f%% of JPEG decode), %8.1f as paged (%5.1f%%), "
      "max |gpu - cpu| %u\n",
      n, raw, 100 * raw / decode_rate, paged, 100 * paged / decode_rate, max_difference);
}

int runComposite(int argc, char** argv) {
  const double seconds = std::stod(argument(argc, argv, "--seconds", "2"));
  auto set = check(
      BrushSet::prepare(realBrushes(argument(argc, argv, "--images", nullptr)), {}, 256, 256));
  std::unique_ptr<GlContext> context;
  std::unique_ptr<GpuCompositor> gpu;
  if (hasFlag(argc, argv, "--gpu")) {
    context = check(GlContext::createHeadless());
    gpu = check(GpuCompositor::create(set));
    std::printf("GPU compositor on %s\n", context->description().c_str());
  }
  std::mt19937_64 rng(1);
  std::printf("%-10s %12s %12s %12s %8s %14s %8s %8s\n", "instances", "tiles/s", "JPEG dec/s",
              "ratio", "us/tile", "analysed t/s", "ratio", "kept");
  for (uint32_t n : {10u, 100u, 1000u}) {
    std::vector<std::vector<BrushInstance>> tiles;
    for (int t = 0; t < 8; ++t) tiles.push_back(tileInstances(n, 6, rng));
    const TileGeometry geometry{0, 0, 0, 256, 0, 256, 256};
    Image out;
    uint64_t composited = 0;
    const auto start = Clock::now();
    while (std::chrono::duration<double>(Clock::now() - start).count() < seconds) {
      check(compositeTile(*set, geometry, tiles[composited % tiles.size()], out));
      ++composited;
    }
    const double composite_rate =
        composited / std::chrono::duration<double>(Clock::now() - start).count();
    // The same tiles as a page stores them: covered instances dropped, the rest clipped.
    std::vector<detail::TileAnalysis> analysed;
    size_t kept = 0;
    for (const auto& instances : tiles) {
      analysed.push_back(check(detail::analyseTile(*set, geometry, instances, {})));
      kept += analysed.back().kept.size();
    }
    uint64_t paged = 0;
    const auto paged_start = Clock::now();
    while (std::chrono::duration<double>(Clock::now() - paged_start).count() < seconds) {
      const detail::TileAnalysis& a = analysed[paged % analysed.size()];
      check(compositeTile(*set, geometry, a.kept, out, a.clips));
      ++paged;
    }
    const double paged_rate =
        paged / std::chrono::duration<double>(Clock::now() - paged_start).count();
    // The same tiles baked: RGB JPEG at quality 85, decoded with the archive's decoder.
    std::vector<std::vector<uint8_t>> payloads;
    for (const auto& instances : tiles) {
      check(compositeTile(*set, geometry, instances, out));
      Image rgb(256, 256, 3);
      for (size_t i = 0; i < 256 * 256; ++i) std::memcpy(&rgb.texels[i * 3], &out.texels[i * 4], 3);
      payloads.push_back(check(detail::encodeTile(Codec::kJpeg, rgb.view(), {})));
    }
    Image decoded(256, 256, 3);
    CodecScratch scratch;
    uint64_t decodes = 0;
    const auto decode_start = Clock::now();
    while (std::chrono::duration<double>(Clock::now() - decode_start).count() < seconds) {
      check(detail::decodeTile(Codec::kJpeg, payloads[decodes % payloads.size()], decoded, nullptr,
                               &scratch));
      ++decodes;
    }
    const double decode_rate =
        decodes / std::chrono::duration<double>(Clock::now() - decode_start).count();
    std::printf("%-10u %12.0f %12.0f %11.0f%% %8.0f %14.0f %7.0f%% %8.1f\n", n, composite_rate,
                decode_rate, 100 * composite_rate / decode_rate, 1e6 / composite_rate, paged_rate,
                100 * paged_rate / decode_rate, double(kept) / tiles.size());
    if (gpu) runGpuComposite(*gpu, n, seconds, tiles, analysed, decode_rate);
  }
  return 0;
}

int runQuery(int argc, char** argv) {
  auto db = check(openBrushDatabase(argv[2], false));
  const uint32_t tiles = uint32_t(std::stoul(argument(argc, argv, "--tiles", "2000")));
  const uint32_t level = uint32_t(std::stoul(argument(argc, argv, "--level", "0")));
  const TextureExtent extent = check(db->textureExtent());
  std::mt19937_64 rng(7);
  std::vector<double> micros;
  uint64_t found_total = 0;
  std::vector<BrushInstance> found;
  for (uint32_t i = 0; i < tiles; ++i) {
    const uint32_t side = 256u << level;
    TileGeometry tile{level,
                      uint32_t(rng() % std::max(1u, extent.width_px / side)),
                      uint32_t(rng() % std::max(1u, extent.height_px / side)),
                      256,
                      0,
                      extent.width_px,
                      extent.height_px};
    found.clear();
    const auto start = Clock::now();
    check(db->query(tileQueryBox(tile), found));
    micros.push_back(std::chrono::duration<double, std::micro>(Clock::now() - start).count());
    found_total += found.size();
  }
  std::sort(micros.begin(), micros.end());
  double mean = 0;
  for (double m : micros) mean += m;
  mean /= micros.size();
  std::printf(
      "%s (%s): %llu instances, level %u, %u tiles: mean %.1f us, median %.1f us, p99 %.1f "
      "us, %.1f instances per tile\n",
      argv[2], db->backend(), (unsigned long long)check(db->instanceCount()), level, tiles, mean,
      micros[micros.size() / 2], micros[micros.size() * 99 / 100], double(found_total) / tiles);
  return 0;
}

}  // namespace
}  // namespace tessera

int main(int argc, char** argv) {
  const std::string command = argc > 1 ? argv[1] : "";
  if (command == "setup" && argc > 2) return tessera::runSetup(argc, argv);
  if (command == "composite") return tessera::runComposite(argc, argv);
  if (command == "query" && argc > 2) return tessera::runQuery(argc, argv);
  std::fprintf(stderr,
               "usage: tessera-procedural-bench setup DB --images DIR --size WxH --count N "
               "[--seed S] | composite --images DIR [--seconds S] [--gpu] | query DB [--tiles N] "
               "[--level L]\n");
  return 2;
}
