#pragma once
// How the format fuzzers read their inputs: a few bytes of parameters (an image's geometry, a
// file size) before the bytes under test, so that one input fixes everything the parser sees.
// Shared by the fuzzers and by make_format_corpus.cpp, which writes seeds in this layout.

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <span>
#include <vector>

#include <tessera/format.h>

namespace tessera::fuzz {

[[noreturn]] inline void die(const char* fuzzer, const char* what) {
  std::fprintf(stderr, "%s: %s\n", fuzzer, what);
  std::abort();
}

/// Reads fixed-size little-endian fields from the front of an input.
class InputReader {
 public:
  explicit InputReader(std::span<const uint8_t> bytes) : bytes_(bytes) {}
  bool has(size_t count) const { return bytes_.size() - pos_ >= count; }
  uint64_t take(size_t count) {
    uint64_t value = 0;
    for (size_t i = 0; i < count; ++i) value |= uint64_t(bytes_[pos_ + i]) << (8 * i);
    pos_ += count;
    return value;
  }
  std::span<const uint8_t> rest() const { return bytes_.subspan(pos_); }

 private:
  std::span<const uint8_t> bytes_;
  size_t pos_ = 0;
};

/// An image's geometry in 14 bytes: width and height (u24 each), channels, log2 of the tile
/// size, border, log2 of the page side, level, page x, page y, and a spare byte.
struct GeometryInput {
  ImageInfo info;
  uint32_t level = 0;
  uint32_t page_x = 0;
  uint32_t page_y = 0;
};
inline constexpr size_t kGeometryInputBytes = 14;

inline GeometryInput readGeometry(InputReader& reader) {
  GeometryInput geometry;
  ImageInfo& info = geometry.info;
  info.width_px = uint32_t(reader.take(3));
  info.height_px = uint32_t(reader.take(3));
  info.channels = uint32_t(reader.take(1));
  info.tile_size_px = 1u << (reader.take(1) & 15);
  info.border_px = uint32_t(reader.take(1));
  info.page_tiles_log2 = uint32_t(reader.take(1));
  geometry.level = uint32_t(reader.take(1));
  geometry.page_x = uint32_t(reader.take(1));
  geometry.page_y = uint32_t(reader.take(1));
  reader.take(1);
  if (info.width_px > 0 && info.height_px > 0 && info.tile_size_px > 0)
    info.level_count = levelCountFor(info.width_px, info.height_px, info.tile_size_px);
  return geometry;
}

inline void appendLe(std::vector<uint8_t>& out, uint64_t value, size_t count) {
  for (size_t i = 0; i < count; ++i) out.push_back(uint8_t(value >> (8 * i)));
}

inline std::vector<uint8_t> geometryBytes(const ImageInfo& info, uint32_t level, uint32_t page_x,
                                          uint32_t page_y) {
  std::vector<uint8_t> out;
  appendLe(out, info.width_px, 3);
  appendLe(out, info.height_px, 3);
  appendLe(out, info.channels, 1);
  uint32_t log2 = 0;
  while ((1u << log2) < info.tile_size_px) ++log2;
  appendLe(out, log2, 1);
  appendLe(out, info.border_px, 1);
  appendLe(out, info.page_tiles_log2, 1);
  appendLe(out, level, 1);
  appendLe(out, page_x, 1);
  appendLe(out, page_y, 1);
  appendLe(out, 0, 1);
  return out;
}

}  // namespace tessera::fuzz
