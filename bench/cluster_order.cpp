// Compares payload clustering orders on clip-region reads (docs/format.md, "Clustering").
// Takes the real payload sizes of an archive, lays them out in each order without writing a
// file, and replays clip regions (Backes et al., eq. 3-4: n = ceil(max(sw, sh) / t) * 2 tiles
// around floor(f / t)) as reads, merging ranges whose gap is under 64 KiB.
#include <algorithm>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include <fmt/format.h>

#include <tessera/archive.h>

#include "format/tile_order.h"

using namespace tessera;

namespace {

struct Range {
  uint64_t begin, end;
};

struct ReadCost {
  uint64_t reads = 0;
  uint64_t bytes_read = 0;
  uint64_t bytes_needed = 0;
};

ReadCost mergedReads(std::vector<Range> ranges, uint64_t max_gap) {
  ReadCost cost;
  for (const Range& r : ranges) cost.bytes_needed += r.end - r.begin;
  std::sort(ranges.begin(), ranges.end(),
            [](const Range& a, const Range& b) { return a.begin < b.begin; });
  for (size_t i = 0; i < ranges.size();) {
    uint64_t begin = ranges[i].begin, end = ranges[i].end;
    size_t j = i + 1;
    while (j < ranges.size() && ranges[j].begin <= end + max_gap)
      end = std::max(end, ranges[j++].end);
    ++cost.reads;
    cost.bytes_read += end - begin;
    i = j;
  }
  return cost;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: tessera-cluster-bench ARCHIVE [screen_w screen_h] [regions]\n");
    return 2;
  }
  uint32_t screen_w = argc > 3 ? std::stoul(argv[2]) : 1920,
           screen_h = argc > 3 ? std::stoul(argv[3]) : 1080;
  int regions = argc > 4 ? std::stoi(argv[4]) : 200;
  auto archive = Archive::openFile(argv[1]);
  if (!archive) {
    std::fprintf(stderr, "%s\n", archive.error().message.c_str());
    return 1;
  }
  const ImageInfo& info = (*archive)->images()[0];
  // Payload sizes per tile; non-encoded tiles cost nothing.
  std::vector<std::vector<uint64_t>> sizes(info.level_count);
  for (uint32_t l = 0; l < info.level_count; ++l) {
    sizes[l].resize(size_t(info.tilesX(l)) * info.tilesY(l));
    for (uint32_t y = 0; y < info.tilesY(l); ++y)
      for (uint32_t x = 0; x < info.tilesX(l); ++x) {
        auto entry = (*archive)->tileEntry({0, l, x, y});
        if (!entry) return 1;
        sizes[l][size_t(y) * info.tilesX(l) + x] = entry->length_bytes;
      }
  }
  const uint32_t t = info.tile_size_px;
  const uint32_t n = (std::max(screen_w, screen_h) + t - 1) / t * 2;  // eq. 3
  std::printf(
      "archive %s: %ux%u, %u px tiles, clip region %u x %u tiles (%ux%u screen), %d "
      "random centres per level\n\n",
      argv[1], info.width_px, info.height_px, t, n, n, screen_w, screen_h, regions);
  std::printf("| order | case | reads per region | bytes read / needed |\n|---|---|---|---|\n");
  const struct {
    TileOrder order;
    const char* name;
  } orders[] = {{TileOrder::kHilbert, "hilbert"},
                {TileOrder::kQuadtree, "quadtree (depth-first)"},
                {TileOrder::kRowMajor, "row-major"}};
  for (const auto& o : orders) {
    // Offsets in this order.
    std::vector<std::vector<uint64_t>> offset(info.level_count);
    for (uint32_t l = 0; l < info.level_count; ++l) offset[l].resize(sizes[l].size());
    uint64_t pos = 0;
    for (const TileId& tile : detail::tileOrder(info, 0, o.order)) {
      size_t slot = size_t(tile.y) * info.tilesX(tile.level) + tile.x;
      offset[tile.level][slot] = pos;
      pos += sizes[tile.level][slot];
    }
    auto regionRanges = [&](uint32_t level, int64_t cx, int64_t cy, std::vector<Range>& out) {
      int64_t x0 = cx - n / 2, y0 = cy - n / 2;
      for (int64_t y = std::max<int64_t>(0, y0); y < std::min<int64_t>(info.tilesY(level), y0 + n);
           ++y)
        for (int64_t x = std::max<int64_t>(0, x0);
             x < std::min<int64_t>(info.tilesX(level), x0 + n); ++x) {
          size_t slot = size_t(y) * info.tilesX(level) + x;
          if (sizes[level][slot])
            out.push_back({offset[level][slot], offset[level][slot] + sizes[level][slot]});
        }
    };
    for (int kind = 0; kind < 2; ++kind) {
      std::mt19937_64 rng(42);
      ReadCost total;
      int count = 0;
      for (uint32_t level = 0; level < info.level_count; ++level) {
        if (info.tilesX(level) <= n && info.tilesY(level) <= n && level > 0) continue;
        for (int r = 0; r < regions; ++r) {
          // Centre in level-0 pixels; each level's clip centre is floor(f / t) there (eq. 4).
          double fx = std::uniform_real_distribution<double>(0, info.width_px)(rng);
          double fy = std::uniform_real_distribution<double>(0, info.height_px)(rng);
          std::vector<Range> ranges;
          uint32_t last_level = kind == 0 ? level : info.level_count - 1;
          for (uint32_t l = level; l <= last_level; ++l)
            regionRanges(l, int64_t(fx / (1u << l) / t), int64_t(fy / (1u << l) / t), ranges);
          ReadCost cost = mergedReads(ranges, 64 * 1024);
          total.reads += cost.reads;
          total.bytes_read += cost.bytes_read;
          total.bytes_needed += cost.bytes_needed;
          ++count;
        }
      }
      std::printf("| %s | %s | %.1f | %.3f |\n", o.name,
                  kind == 0 ? "one level's clip region"
                            : "jump: clip regions of that level and all coarser",
                  double(total.reads) / count,
                  double(total.bytes_read) / double(total.bytes_needed));
    }
  }
  return 0;
}
