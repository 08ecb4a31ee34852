#include "export/pmtiles.h"

#include <cstddef>
#include <iterator>
#include <utility>

namespace tessera::detail::pmtiles {

namespace {

void putVarint(std::vector<uint8_t>& out, uint64_t value) {
  while (value >= 0x80) {
    out.push_back(uint8_t(value) | 0x80);
    value >>= 7;
  }
  out.push_back(uint8_t(value));
}

void putLe(std::vector<uint8_t>& out, size_t at, uint64_t value, int bytes) {
  for (int i = 0; i < bytes; ++i) out[at + size_t(i)] = uint8_t(value >> (8 * i));
}

}  // namespace

uint64_t tileId(uint32_t z, uint32_t x, uint32_t y) {
  // (4^z - 1) / 3 tiles on the coarser zooms.
  uint64_t id = ((uint64_t(1) << (2 * z)) - 1) / 3;
  const uint64_t n = uint64_t(1) << z;
  uint64_t tx = x, ty = y;
  for (uint64_t s = n / 2; s > 0; s /= 2) {
    const uint64_t rx = (tx & s) ? 1 : 0;
    const uint64_t ry = (ty & s) ? 1 : 0;
    id += s * s * ((3 * rx) ^ ry);
    // Rotate the quadrant so the curve continues where the previous one ended.
    if (ry == 0) {
      if (rx == 1) {
        tx = n - 1 - tx;
        ty = n - 1 - ty;
      }
      std::swap(tx, ty);
    }
  }
  return id;
}

std::vector<uint8_t> encodeDirectory(const std::vector<Entry>& entries) {
  std::vector<uint8_t> out;
  putVarint(out, entries.size());
  uint64_t previous_id = 0;
  for (const Entry& entry : entries) {
    putVarint(out, entry.tile_id - previous_id);
    previous_id = entry.tile_id;
  }
  for (const Entry& entry : entries) putVarint(out, entry.run_length);
  for (const Entry& entry : entries) putVarint(out, entry.length);
  for (size_t i = 0; i < entries.size(); ++i) {
    const bool follows =
        i > 0 && entries[i].offset == entries[i - 1].offset + entries[i - 1].length;
    putVarint(out, follows ? 0 : entries[i].offset + 1);
  }
  return out;
}

std::vector<uint8_t> encodeHeader(const Header& header) {
  std::vector<uint8_t> out(kHeaderBytes, 0);
  const char magic[] = "PMTiles";
  for (size_t i = 0; i < 7; ++i) out[i] = uint8_t(magic[i]);
  out[7] = 3;
  const uint64_t fields[] = {
      header.root_offset,     header.root_bytes,   header.metadata_offset,  header.metadata_bytes,
      header.leaves_offset,   header.leaves_bytes, header.tile_data_offset, header.tile_data_bytes,
      header.addressed_tiles, header.tile_entries, header.tile_contents};
  for (size_t i = 0; i < std::size(fields); ++i) putLe(out, 8 + 8 * i, fields[i], 8);
  out[96] = header.clustered ? 1 : 0;
  out[97] = 1;  // internal compression: none
  out[98] = 1;  // tile compression: none
  out[99] = uint8_t(header.tile_type);
  out[100] = header.min_zoom;
  out[101] = header.max_zoom;
  // A picture has no longitude: it is placed as web maps place XYZ tiles, zoom 0 the whole
  // Web Mercator square, so the bounds are the world's and the centre is 0, 0.
  constexpr int32_t kLonE7 = 1'800'000'000, kLatE7 = 850'511'287;
  putLe(out, 102, uint32_t(-kLonE7), 4);
  putLe(out, 106, uint32_t(-kLatE7), 4);
  putLe(out, 110, uint32_t(kLonE7), 4);
  putLe(out, 114, uint32_t(kLatE7), 4);
  out[118] = header.min_zoom;
  return out;
}

}  // namespace tessera::detail::pmtiles
