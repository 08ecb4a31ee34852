#include "support/reference_pyramid.h"

#include <algorithm>
#include <cstring>
#include <sstream>

namespace tessera::test {

namespace {

bool hasAlpha(uint32_t channels) {
  return channels == 2 || channels == 4;
}

const uint8_t* texelAt(const Image& image, uint32_t x, uint32_t y) {
  return image.texels.data() + (size_t(y) * image.width_px + x) * image.channels;
}

}  // namespace

Image referenceDownsample(const Image& level) {
  const uint32_t w = level.width_px, h = level.height_px, channels = level.channels;
  Image out((w + 1) / 2, (h + 1) / 2, channels);
  for (uint32_t oy = 0; oy < out.height_px; ++oy) {
    for (uint32_t ox = 0; ox < out.width_px; ++ox) {
      const uint32_t xs[2] = {2 * ox, std::min(2 * ox + 1, w - 1)};
      const uint32_t ys[2] = {2 * oy, std::min(2 * oy + 1, h - 1)};
      const uint8_t* block[4] = {texelAt(level, xs[0], ys[0]), texelAt(level, xs[1], ys[0]),
                                 texelAt(level, xs[0], ys[1]), texelAt(level, xs[1], ys[1])};
      uint8_t* o = out.texels.data() + (size_t(oy) * out.width_px + ox) * channels;
      if (!hasAlpha(channels)) {
        for (uint32_t c = 0; c < channels; ++c) {
          uint32_t sum = block[0][c] + block[1][c] + block[2][c] + block[3][c];
          o[c] = uint8_t((sum + 2) >> 2);
        }
        continue;
      }
      const uint32_t a = channels - 1;
      uint32_t alpha = block[0][a] + block[1][a] + block[2][a] + block[3][a];
      if (alpha == 0) {
        std::fill(o, o + channels, uint8_t(0));
        continue;
      }
      for (uint32_t c = 0; c < a; ++c) {
        uint64_t weighted = 0;
        for (const uint8_t* t : block) weighted += uint64_t(t[c]) * t[a];
        o[c] = uint8_t((weighted + alpha / 2) / alpha);
      }
      o[a] = uint8_t((alpha + 2) >> 2);
    }
  }
  return out;
}

Image referenceFloorDownsample(const Image& level) {
  const uint32_t w = level.width_px, h = level.height_px, channels = level.channels;
  Image out((w + 1) / 2, (h + 1) / 2, channels);
  for (uint32_t oy = 0; oy < out.height_px; ++oy)
    for (uint32_t ox = 0; ox < out.width_px; ++ox)
      for (uint32_t c = 0; c < channels; ++c) {
        uint32_t sum = 0;
        for (uint32_t y : {2 * oy, std::min(2 * oy + 1, h - 1)})
          for (uint32_t x : {2 * ox, std::min(2 * ox + 1, w - 1)}) sum += texelAt(level, x, y)[c];
        out.row(oy)[size_t(ox) * channels + c] = uint8_t(sum / 4);
      }
  return out;
}

ReferencePyramid::ReferencePyramid(Image level0, bool floor_average) {
  levels_.push_back(std::move(level0));
  while (levels_.back().width_px > 1 || levels_.back().height_px > 1)
    levels_.push_back(floor_average ? referenceFloorDownsample(levels_.back())
                                    : referenceDownsample(levels_.back()));
}

uint32_t ReferencePyramid::levelCount(uint32_t tile_size_px) const {
  uint32_t level = 0;
  while (levels_[level].width_px > tile_size_px || levels_[level].height_px > tile_size_px) ++level;
  return level + 1;
}

uint32_t ReferencePyramid::tilesX(uint32_t level, uint32_t tile_size_px) const {
  return (levels_[level].width_px + tile_size_px - 1) / tile_size_px;
}

uint32_t ReferencePyramid::tilesY(uint32_t level, uint32_t tile_size_px) const {
  return (levels_[level].height_px + tile_size_px - 1) / tile_size_px;
}

ReferenceTile ReferencePyramid::tile(uint32_t level, uint32_t x, uint32_t y, uint32_t tile_size_px,
                                     uint32_t border_px) const {
  const Image& source = levels_[level];
  const uint32_t side = tile_size_px + 2 * border_px, channels = source.channels;
  ReferenceTile out;
  out.texels = Image(side, side, channels);
  // The clamped column of every tile column, computed once per tile.
  std::vector<uint32_t> columns(side);
  for (uint32_t sx = 0; sx < side; ++sx)
    columns[sx] = uint32_t(std::clamp<int64_t>(int64_t(x) * tile_size_px - border_px + sx, 0,
                                               int64_t(source.width_px) - 1));
  for (uint32_t sy = 0; sy < side; ++sy) {
    int64_t ly = std::clamp<int64_t>(int64_t(y) * tile_size_px - border_px + sy, 0,
                                     int64_t(source.height_px) - 1);
    const uint8_t* row = texelAt(source, 0, uint32_t(ly));
    uint8_t* dst = out.texels.texels.data() + size_t(sy) * side * channels;
    for (uint32_t sx = 0; sx < side; ++sx)
      for (uint32_t c = 0; c < channels; ++c)
        dst[sx * channels + c] = row[columns[sx] * channels + c];
  }
  const std::vector<uint8_t>& bytes = out.texels.texels;
  bool all_zero = std::all_of(bytes.begin(), bytes.end(), [](uint8_t v) { return v == 0; });
  bool all_equal = true;
  for (size_t i = channels; i < bytes.size() && all_equal; i += channels)
    all_equal = std::memcmp(&bytes[i], &bytes[0], channels) == 0;
  if (all_zero && hasAlpha(channels)) {
    out.kind = TileKind::kEmpty;
  } else if (all_equal) {
    out.kind = TileKind::kUniform;
    for (uint32_t c = 0; c < channels; ++c) out.uniform_rgba |= uint32_t(bytes[c]) << (8 * c);
  }
  return out;
}

Image ReferencePyramid::region(uint32_t level, int64_t x, int64_t y, uint32_t width,
                               uint32_t height) const {
  const Image& source = levels_[level];
  Image out(width, height, source.channels);
  for (uint32_t ry = 0; ry < height; ++ry) {
    for (uint32_t rx = 0; rx < width; ++rx) {
      int64_t lx = x + rx, ly = y + ry;
      if (lx < 0 || ly < 0 || lx >= source.width_px || ly >= source.height_px) continue;
      std::memcpy(out.texels.data() + (size_t(ry) * width + rx) * source.channels,
                  texelAt(source, uint32_t(lx), uint32_t(ly)), source.channels);
    }
  }
  return out;
}

Image makePatternImage(uint32_t width_px, uint32_t height_px, uint32_t channels, uint32_t seed) {
  Image image(width_px, height_px, channels);
  const bool alpha = hasAlpha(channels);
  for (uint32_t y = 0; y < height_px; ++y) {
    for (uint32_t x = 0; x < width_px; ++x) {
      uint8_t* t = image.texels.data() + (size_t(y) * width_px + x) * channels;
      uint32_t hash = (x * 0x9E3779B1u) ^ (y * 0x85EBCA77u) ^ (seed * 0xC2B2AE3Du);
      hash ^= hash >> 15;
      hash *= 0x2C1B3C6Du;
      hash ^= hash >> 12;
      const bool flat = x < width_px / 3 && y < height_px / 2;
      const bool hole = alpha && x >= 2 * width_px / 3 && y >= height_px / 2;
      for (uint32_t c = 0; c < channels; ++c) {
        if (flat)
          t[c] = uint8_t(40 + 50 * c);
        else if (hole)
          t[c] = 0;
        else
          t[c] = uint8_t(((x + 3 * y) * (c + 1) + (hash >> (8 * c))) & 0xFF);
      }
      if (!alpha || flat || hole) {
        if (alpha && flat) t[channels - 1] = 255;
        continue;
      }
      // Mostly opaque, some transparent (with colour left in) and some translucent texels.
      uint32_t pick = (hash >> 24) % 8;
      t[channels - 1] = pick < 5 ? 255 : pick == 5 ? 0 : uint8_t(hash >> 16);
    }
  }
  return image;
}

std::string firstDifference(const Image& expected, const Image& actual) {
  std::ostringstream out;
  if (expected.width_px != actual.width_px || expected.height_px != actual.height_px ||
      expected.channels != actual.channels) {
    out << "geometry " << actual.width_px << "x" << actual.height_px << "x" << actual.channels
        << ", expected " << expected.width_px << "x" << expected.height_px << "x"
        << expected.channels;
    return out.str();
  }
  for (size_t i = 0; i < expected.texels.size(); ++i) {
    if (expected.texels[i] != actual.texels[i]) {
      size_t texel = i / expected.channels;
      out << "texel (" << texel % expected.width_px << "," << texel / expected.width_px
          << ") channel " << i % expected.channels << ": " << int(actual.texels[i]) << ", expected "
          << int(expected.texels[i]);
      return out.str();
    }
  }
  return "";
}

}  // namespace tessera::test
