#include "format/tile_order.h"

#include <algorithm>
#include <bit>

namespace tessera::detail {

uint64_t hilbertIndex(uint32_t bits, uint32_t x, uint32_t y) {
  // The classic rotate-and-flip walk from the most significant bit down.
  uint64_t index = 0;
  for (uint32_t s = bits == 0 ? 0 : (1u << (bits - 1)); s > 0; s >>= 1) {
    uint32_t rx = (x & s) ? 1 : 0;
    uint32_t ry = (y & s) ? 1 : 0;
    index += uint64_t(s) * s * ((3 * rx) ^ ry);
    if (ry == 0) {
      if (rx == 1) {
        x = s - 1 - (x & (s - 1));
        y = s - 1 - (y & (s - 1));
      }
      std::swap(x, y);
    }
    x &= s - 1;
    y &= s - 1;
  }
  return index;
}

namespace {

void appendLevelHilbert(const ImageInfo& info, uint32_t image, uint32_t level,
                        std::vector<TileId>& out) {
  uint32_t tiles_x = info.tilesX(level), tiles_y = info.tilesY(level);
  uint32_t bits = std::bit_width(std::max(tiles_x, tiles_y) - 1);
  struct Keyed {
    uint64_t key;
    uint32_t x, y;
  };
  std::vector<Keyed> keyed;
  keyed.reserve(size_t(tiles_x) * tiles_y);
  for (uint32_t y = 0; y < tiles_y; ++y)
    for (uint32_t x = 0; x < tiles_x; ++x) keyed.push_back({hilbertIndex(bits, x, y), x, y});
  std::sort(keyed.begin(), keyed.end(),
            [](const Keyed& a, const Keyed& b) { return a.key < b.key; });
  for (const Keyed& k : keyed) out.push_back({image, level, k.x, k.y});
}

void appendSubtree(const ImageInfo& info, uint32_t image, uint32_t level, uint32_t x, uint32_t y,
                   std::vector<TileId>& out) {
  if (x >= info.tilesX(level) || y >= info.tilesY(level)) return;
  out.push_back({image, level, x, y});
  if (level == 0) return;
  // Children in Z order: the four quadrants of this tile one level finer.
  for (uint32_t child = 0; child < 4; ++child)
    appendSubtree(info, image, level - 1, 2 * x + (child & 1), 2 * y + (child >> 1), out);
}

}  // namespace

std::vector<TileId> tileOrder(const ImageInfo& info, uint32_t image, TileOrder order) {
  std::vector<TileId> out;
  uint64_t total = 0;
  for (uint32_t level = 0; level < info.level_count; ++level)
    total += uint64_t(info.tilesX(level)) * info.tilesY(level);
  out.reserve(total);
  uint32_t coarsest = info.level_count - 1;
  switch (order) {
    case TileOrder::kHilbert:
      for (uint32_t level = coarsest + 1; level-- > 0;) appendLevelHilbert(info, image, level, out);
      break;
    case TileOrder::kRowMajor:
      for (uint32_t level = coarsest + 1; level-- > 0;)
        for (uint32_t y = 0; y < info.tilesY(level); ++y)
          for (uint32_t x = 0; x < info.tilesX(level); ++x) out.push_back({image, level, x, y});
      break;
    case TileOrder::kQuadtree:
      for (uint32_t y = 0; y < info.tilesY(coarsest); ++y)
        for (uint32_t x = 0; x < info.tilesX(coarsest); ++x)
          appendSubtree(info, image, coarsest, x, y, out);
      break;
  }
  return out;
}

}  // namespace tessera::detail
