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
//   storage DB --out DIR [--qualities Q,Q...] [--threads N] [--frame-budget-ms MS]
//                                                           the mixed archive's size against
//                                                           baked-only JPEG archives of the same
//                                                           pixels, at the PSNR of its baked
//                                                           tiles (docs/procedural.md)
// DB is an SQLite file or a PostGIS connection string.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <fmt/format.h>

#include <tessera/archive.h>
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

/// Squared error and channel values compared, for a PSNR.
struct ErrorSum {
  double squared = 0;
  uint64_t values = 0;
  double psnr() const {
    if (values == 0) return 0;
    const double mse = squared / double(values);
    return mse == 0 ? 99.0 : 10 * std::log10(255.0 * 255.0 / mse);
  }
};

/// Every tile of `archive` against the same tile of `reference` (the composited pixels, baked
/// losslessly): the error over all tiles, and over the tiles `archive` stores encoded.
void compareArchives(const Archive& archive, const Archive& reference, ErrorSum* all,
                     ErrorSum* encoded) {
  const ImageInfo& info = reference.images()[0];
  CodecScratch scratch;
  for (uint32_t level = 0; level < info.level_count; ++level) {
    for (uint32_t y = 0; y < info.tilesY(level); ++y) {
      for (uint32_t x = 0; x < info.tilesX(level); ++x) {
        const TileId id{0, level, x, y};
        const Image a = check(archive.readTile(id, &scratch));
        const Image r = check(reference.readTile(id, &scratch));
        if (a.texels.size() != r.texels.size()) die("tiles of different shapes");
        ErrorSum tile;
        for (size_t i = 0; i < a.texels.size(); ++i) {
          const double d = double(a.texels[i]) - double(r.texels[i]);
          tile.squared += d * d;
        }
        tile.values = a.texels.size();
        all->squared += tile.squared;
        all->values += tile.values;
        if (encoded && check(archive.tileEntry(id)).kind == TileKind::kEncoded) {
          encoded->squared += tile.squared;
          encoded->values += tile.values;
        }
      }
    }
  }
}

ProceduralBuildReport build(ProceduralBuildOptions options, const std::string& name) {
  const auto start = Clock::now();
  ProceduralBuildReport report = check(buildProceduralArchive(options));
  std::fprintf(stderr, "%s: %llu bytes, %llu procedural tiles of %llu, %.0f s\n", name.c_str(),
               (unsigned long long)report.output_bytes, (unsigned long long)report.tiles_procedural,
               (unsigned long long)report.tiles_total,
               std::chrono::duration<double>(Clock::now() - start).count());
  return report;
}

// The storage target: the reference is every tile baked losslessly (the composited
// pixels), the mixed archive stores JPEG (quality 85) where baked, and each baked-only archive
// is JPEG of the composited pixels at one quality. The mixed archive is compared with the
// baked-only size interpolated at the PSNR its baked tiles achieve.
int runStorage(int argc, char** argv) {
  const std::string out = argument(argc, argv, "--out", nullptr);
  ProceduralBuildOptions base;
  base.database = argv[2];
  base.threads = uint32_t(std::stoul(argument(argc, argv, "--threads", "2")));
  base.frame_budget_ms = std::stod(argument(argc, argv, "--frame-budget-ms", "4"));
  ProceduralBuildOptions reference_options = base;
  reference_options.output = out + "/reference.tess";
  reference_options.codec = Codec::kZstd;
  reference_options.bake_all = true;
  build(reference_options, "reference (zstd, every tile baked)");
  ProceduralBuildOptions mixed_options = base;
  mixed_options.output = out + "/mixed.tess";
  const ProceduralBuildReport mixed = build(mixed_options, "mixed (JPEG 85 where baked)");
  auto reference = check(Archive::openFile(reference_options.output));
  auto mixed_archive = check(Archive::openFile(mixed_options.output));
  ErrorSum mixed_all, mixed_baked;
  compareArchives(*mixed_archive, *reference, &mixed_all, &mixed_baked);
  std::printf(
      "mixed: %llu bytes, %llu of %llu tiles procedural, %llu baked; PSNR of its baked "
      "tiles %.2f dB, of all tiles %.2f dB\n",
      (unsigned long long)mixed.output_bytes, (unsigned long long)mixed.tiles_procedural,
      (unsigned long long)mixed.tiles_total, (unsigned long long)mixed.tiles_baked,
      mixed_baked.psnr(), mixed_all.psnr());
  std::vector<std::pair<double, double>> curve;  // (PSNR, bytes) of the baked-only archives
  std::stringstream qualities(argument(argc, argv, "--qualities", "50,70,80,85,90,95"));
  for (std::string q; std::getline(qualities, q, ',');) {
    ProceduralBuildOptions baked_options = base;
    baked_options.output = out + "/baked-q" + q + ".tess";
    baked_options.quality = std::stoi(q);
    baked_options.bake_all = true;
    const ProceduralBuildReport baked = build(baked_options, "baked-only JPEG " + q);
    ErrorSum all;
    compareArchives(*check(Archive::openFile(baked_options.output)), *reference, &all, nullptr);
    std::printf("baked-only JPEG quality %3s: %llu bytes, PSNR %.2f dB, mixed / this %.1f%%\n",
                q.c_str(), (unsigned long long)baked.output_bytes, all.psnr(),
                100.0 * mixed.output_bytes / baked.output_bytes);
    curve.emplace_back(all.psnr(), double(baked.output_bytes));
  }
  std::sort(curve.begin(), curve.end());
  const double target = mixed_baked.psnr();
  for (size_t i = 1; i < curve.size(); ++i) {
    if (curve[i - 1].first <= target && target <= curve[i].first) {
      const double t = (target - curve[i - 1].first) / (curve[i].first - curve[i - 1].first);
      const double bytes = curve[i - 1].second + t * (curve[i].second - curve[i - 1].second);
      std::printf("baked-only at %.2f dB (interpolated): %.0f bytes; mixed / baked-only = %.2f%%\n",
                  target, bytes, 100.0 * mixed.output_bytes / bytes);
      return 0;
    }
  }
  std::printf("the mixed archive's %.2f dB lies outside the qualities measured\n", target);
  return 0;
}

}  // namespace
}  // namespace tessera

int main(int argc, char** argv) {
  const std::string command = argc > 1 ? argv[1] : "";
  if (command == "setup" && argc > 2) return tessera::runSetup(argc, argv);
  if (command == "composite") return tessera::runComposite(argc, argv);
  if (command == "query" && argc > 2) return tessera::runQuery(argc, argv);
  if (command == "storage" && argc > 2) return tessera::runStorage(argc, argv);
  std::fprintf(stderr,
               "usage: tessera-procedural-bench setup DB --images DIR --size WxH --count N "
               "[--seed S] | composite --images DIR [--seconds S] [--gpu] | query DB [--tiles N] "
               "[--level L] | storage DB --out DIR [--qualities Q,Q...] [--threads N] "
               "[--frame-budget-ms MS]\n");
  return 2;
}
