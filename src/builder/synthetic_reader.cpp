// Synthetic terrain source. Elevation is fBm value noise (Musgrave's fractional Brownian
// motion, in Ebert et al., "Texturing and Modeling", ch. 16): one octave per power of two
// from half the image down to single pixels. Octaves of 16 px and more are evaluated on a grid
// of points 16 px apart and interpolated bilinearly per pixel, which is exact for the
// bilinear part of each octave and costs about 1/256 of a per-pixel evaluation; only the four
// octaves under 16 px run per pixel. Everything is integer arithmetic with defined overflow
// (uint32 hashing, int32/int64 fixed point), so a spec gives the same bytes on every machine.

#include "synthetic_reader.h"

#include <algorithm>
#include <charconv>
#include <cstdlib>
#include <cstring>
#include <memory>

#include <fmt/format.h>

#include <tessera/format.h>

#include "band_reader.h"

namespace tessera::detail {
namespace {

constexpr int kGridShift = 4;  // coarse octaves on a grid of 16 px
constexpr uint32_t kGridPx = 1u << kGridShift;
constexpr uint32_t kChunkPx = 512;  // pixels coloured per pass; a multiple of kGridPx
constexpr uint32_t kBandRows = kGridPx;
// Lattice values are 12-bit, [-2048, 2048); an octave of amplitude A spans about [-A, A).
constexpr int kLatticeBits = 12;
// Elevation units relative to sea level. The palette spans [kPaletteMin, kPaletteMin + 32768)
// in steps of 32 units.
constexpr int32_t kSeaLevel = -1500;
constexpr int32_t kDeepSea = -1400;  // below this (relative) the sea is one flat colour
constexpr int32_t kPaletteMin = -4096;
constexpr int32_t kRiverMaxElevation = 13000;
constexpr int32_t kRoadMinElevation = 300;
constexpr int32_t kRoadMaxElevation = 11000;
// Half-widths of the line features in 1/16 px (distance to the zero contour of their field).
constexpr int32_t kRiverHalfWidth16 = 24;
constexpr int32_t kStreamHalfWidth16 = 10;
constexpr int32_t kHighwayHalfWidth16 = 20;
constexpr int32_t kRoadHalfWidth16 = 8;
constexpr int32_t kShadeGain = 24;  // brightness change per elevation step, in 1/256 per 256 units

constexpr uint8_t kDeepSeaColour[3] = {22, 50, 92};
constexpr uint8_t kRiverColour[3] = {46, 86, 140};
constexpr uint8_t kStreamColour[3] = {62, 104, 150};
constexpr uint8_t kHighwayColour[3] = {214, 204, 188};
constexpr uint8_t kRoadColour[3] = {158, 146, 124};
constexpr uint8_t kNoDataColour[3] = {0, 0, 0};
constexpr int32_t kPaletteSize = 1024;  // elevation steps of 32 units from kPaletteMin
constexpr int32_t kWetLevels = 17;      // moisture levels, dithered between
constexpr uint32_t kNoiseTableSize = 8192;
constexpr uint32_t kNoiseMask = kNoiseTableSize - 1;

// Chris Wellons' "lowbias32" integer hash (hash-prospector), a full-avalanche 32-bit mix.
inline uint32_t mix(uint32_t h) {
  h ^= h >> 16;
  h *= 0x7feb352dU;
  h ^= h >> 15;
  h *= 0x846ca68bU;
  h ^= h >> 16;
  return h;
}

// Lattice value at column x of a lattice row whose key is mix(row ^ octave seed).
inline int32_t lattice(uint32_t x, uint32_t row_key) {
  return int32_t(mix(x * 0x9e3779b1U ^ row_key) >> (32 - kLatticeBits)) - (1 << (kLatticeBits - 1));
}

// Smoothstep 3t^2 - 2t^3 of the position `frac` inside a cell of 2^cell_shift, in 1/65536.
inline int64_t smoothWeight(uint32_t frac, int cell_shift) {
  const uint64_t t =
      cell_shift <= 16 ? uint64_t(frac) << (16 - cell_shift) : uint64_t(frac) >> (cell_shift - 16);
  return int64_t((t * t * (3 * 65536 - 2 * t)) >> 32);
}

inline int32_t clampInt(int32_t v, int32_t lo, int32_t hi) {
  return v < lo ? lo : v > hi ? hi : v;
}

struct PaletteKey {
  int32_t elevation;  // relative to sea level
  uint8_t dry[3];
  uint8_t wet[3];
};

// Elevation-to-colour ramp; equal elevations make a sharp edge (the coastline).
constexpr PaletteKey kPalette[] = {
    {-4096, {22, 50, 92}, {22, 50, 92}},       {-1400, {22, 50, 92}, {22, 50, 92}},
    {-1, {58, 118, 146}, {54, 112, 140}},      {0, {206, 190, 146}, {186, 174, 134}},
    {350, {196, 182, 132}, {150, 156, 100}},   {700, {172, 162, 104}, {74, 122, 58}},
    {5000, {150, 136, 88}, {52, 96, 46}},      {9000, {126, 112, 82}, {70, 86, 52}},
    {13000, {128, 120, 112}, {108, 104, 98}},  {16000, {162, 157, 152}, {150, 148, 146}},
    {16800, {232, 236, 240}, {232, 236, 240}}, {28672, {250, 250, 252}, {250, 250, 252}},
};

uint32_t seedFor(uint64_t seed, uint32_t a, uint32_t b) {
  return mix(uint32_t(seed) ^ mix(uint32_t(seed >> 32) ^ mix(a * 0x85ebca6bU + b * 0xc2b2ae35U)));
}

int ceilLog2(uint32_t v) {
  int shift = 0;
  while ((uint64_t(1) << shift) < v) ++shift;
  return shift;
}

}  // namespace

Result<SyntheticSpec> parseSyntheticSpec(const std::string& spec) {
  const std::string source = "synthetic:" + spec;
  auto bad = [&](const std::string& why) {
    return fail(
        ErrorCode::kInvalidArgument,
        fmt::format("{}: {} (expected synthetic:WIDTHxHEIGHT[:SEED[:CHANNELS]])", source, why));
  };
  SyntheticSpec out;
  const char* p = spec.data();
  const char* end = spec.data() + spec.size();
  uint64_t width = 0, height = 0;
  auto [after_w, ew] = std::from_chars(p, end, width);
  if (ew != std::errc() || after_w == end || *after_w != 'x') return bad("bad size");
  auto [after_h, eh] = std::from_chars(after_w + 1, end, height);
  if (eh != std::errc()) return bad("bad size");
  p = after_h;
  if (p != end) {
    if (*p != ':') return bad("bad size");
    auto [after_seed, es] = std::from_chars(p + 1, end, out.seed);
    if (es != std::errc() || after_seed == p + 1) return bad("bad seed");
    p = after_seed;
    if (p != end) {
      if (*p != ':') return bad("bad seed");
      uint32_t channels = 0;
      auto [after_c, ec] = std::from_chars(p + 1, end, channels);
      if (ec != std::errc() || after_c != end || (channels != 3 && channels != 4)) {
        return bad("channels must be 3 or 4");
      }
      out.channels = channels;
    }
  }
  if (width == 0 || height == 0) {
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: zero image dimensions ({}x{})", source, width, height));
  }
  if (width > kMaxImageSidePx || height > kMaxImageSidePx) {
    return fail(ErrorCode::kTooLarge,
                fmt::format("{}: image of {}x{} px exceeds the limit of {} px per side", source,
                            width, height, kMaxImageSidePx));
  }
  out.width_px = uint32_t(width);
  out.height_px = uint32_t(height);
  return out;
}

SyntheticGenerator::SyntheticGenerator(const SyntheticSpec& spec) : spec_(spec) {
  grid_cols_ = spec.width_px / kGridPx + 2;  // covers x = width_px, for the slope at the edge
  // Half the smallest power of two covering the image: the whole image spans about two cells
  // of the coarsest octave, so there are a few continents whatever the size.
  const int top_shift =
      std::max(kGridShift + 1, ceilLog2(std::max(spec.width_px, spec.height_px)) - 1);
  uint32_t salt = 0;
  auto add = [&](std::vector<Octave>* octaves, int cell_shift, int32_t amplitude) {
    octaves->push_back({cell_shift, amplitude, seedFor(spec.seed, salt++, uint32_t(cell_shift))});
  };
  // Elevation: relief halves per octave (fBm with H = 1), plus a texture term growing as
  // sqrt(cell) up to 256 px, so that full-resolution tiles of a huge image still show detail
  // (fields, woods, rock) instead of the smooth gradients of pure H = 1 fBm.
  for (int shift = top_shift; shift >= 0; --shift) {
    int32_t amplitude = int32_t((int64_t(20000) << shift) >> top_shift);
    if (shift <= 8) amplitude += (shift % 2 ? 85 : 60) << (shift / 2);  // 60 * sqrt(2^shift)
    add(shift >= kGridShift ? &coarse_[kElevation] : &fine_, shift, amplitude);
  }
  auto addFbm = [&](Field field, int first_shift, int count, int32_t amplitude) {
    for (int i = 0; i < count; ++i) {
      const int shift = std::max(kGridShift, first_shift - i);
      add(&coarse_[field], shift, amplitude >> i);
    }
  };
  addFbm(kMoisture, top_shift - 1, 4, 2048);
  addFbm(kRiver, top_shift - 2, 4, 2048);
  addFbm(kStream, std::min(10, top_shift - 2), 3, 2048);
  addFbm(kHighway, top_shift - 1, 2, 2048);
  addFbm(kRoad, std::min(11, top_shift - 1), 2, 2048);

  for (uint32_t& seed : footprint_seeds_) seed = seedFor(spec.seed, salt++, 0xf00d);
  margin_x_px_ = std::max<uint32_t>(1, spec.width_px / 24);
  margin_y_px_ = std::max<uint32_t>(1, spec.height_px / 24);

  palettes_.resize(size_t(kWetLevels) * kPaletteSize * 3);
  for (int32_t i = 0; i < kPaletteSize; ++i) {
    const int32_t elevation = kPaletteMin + i * 32;
    size_t k = 0;
    while (k + 2 < std::size(kPalette) && kPalette[k + 1].elevation <= elevation) ++k;
    const PaletteKey& a = kPalette[k];
    const PaletteKey& b = kPalette[k + 1];
    const int32_t span = b.elevation - a.elevation;
    const int32_t t = clampInt((elevation - a.elevation) * 256 / std::max(span, 1), 0, 256);
    for (int32_t level = 0; level < kWetLevels; ++level) {
      const int32_t wet = level * 256 / (kWetLevels - 1);
      uint8_t* rgb = palettes_.data() + (size_t(level) * kPaletteSize + size_t(i)) * 3;
      for (int c = 0; c < 3; ++c) {
        const int32_t dry_colour = (a.dry[c] * (256 - t) + b.dry[c] * t) >> 8;
        const int32_t wet_colour = (a.wet[c] * (256 - t) + b.wet[c] * t) >> 8;
        rgb[c] = uint8_t((dry_colour * (256 - wet) + wet_colour * wet) >> 8);
      }
    }
  }
  elevation_.resize(kChunkPx + 1);
  row_fields_.resize(size_t(kFieldCount) * grid_cols_);
  row_slopes_.resize(size_t(kFieldCount) * grid_cols_);
  lattice_.resize(kChunkPx + 2);
  noise_table_.resize(kNoiseTableSize);
  const uint32_t noise_key = seedFor(spec.seed, salt++, 0x5eed);
  for (uint32_t i = 0; i < kNoiseTableSize; ++i) noise_table_[i] = lattice(i, noise_key);
}

void SyntheticGenerator::computeGridRow(uint32_t grid_row, std::vector<int32_t>* values) {
  values->assign(size_t(kFieldCount) * grid_cols_, 0);
  const uint32_t py = grid_row << kGridShift;
  const uint32_t last_px = (grid_cols_ - 1) << kGridShift;
  for (int field = 0; field < kFieldCount; ++field) {
    int32_t* out = values->data() + size_t(field) * grid_cols_;
    for (const Octave& octave : coarse_[field]) {
      const int shift = octave.cell_shift;
      const uint32_t mask = (1u << shift) - 1;
      const uint32_t ly = py >> shift;
      const int64_t wy = smoothWeight(py & mask, shift);
      const uint32_t key0 = mix(ly ^ octave.seed);
      const uint32_t key1 = mix((ly + 1) ^ octave.seed);
      const uint32_t lattice_cols = (last_px >> shift) + 2;
      lattice_.resize(std::max<size_t>(lattice_.size(), lattice_cols));
      for (uint32_t lx = 0; lx < lattice_cols; ++lx) {
        const int64_t a = lattice(lx, key0);
        const int64_t b = lattice(lx, key1);
        lattice_[lx] = int32_t(((a + (((b - a) * wy) >> 16)) * octave.amplitude) >> 11);
      }
      for (uint32_t gx = 0; gx < grid_cols_; ++gx) {
        const uint32_t px = gx << kGridShift;
        const uint32_t lx = px >> shift;
        const int64_t wx = smoothWeight(px & mask, shift);
        const int64_t a = lattice_[lx];
        const int64_t b = lattice_[lx + 1];
        out[gx] += int32_t(a + (((b - a) * wx) >> 16));
      }
    }
  }
}

void SyntheticGenerator::ensureGridRows(uint32_t grid_row) {
  if (grid_row == grid_row_) return;
  if (grid_row_ != UINT32_MAX && grid_row == grid_row_ + 1) {
    std::swap(grid_top_, grid_bottom_);
  } else {
    computeGridRow(grid_row, &grid_top_);
  }
  computeGridRow(grid_row + 1, &grid_bottom_);
  grid_row_ = grid_row;
}

// 1-D fBm along an edge of the image, in about [-3840, 3840], for the scan footprint.
int32_t SyntheticGenerator::footprintNoise(uint32_t t, uint32_t side, uint32_t seed) const {
  int shift = std::max(3, ceilLog2(side) - 2);
  int32_t sum = 0;
  for (int octave = 0; octave < 4; ++octave, shift = std::max(2, shift - 2)) {
    const uint32_t key = mix(seed + uint32_t(octave));
    const uint32_t lx = t >> shift;
    const int32_t frac = int32_t(t & ((1u << shift) - 1));
    const int32_t a = lattice(lx, key);
    const int32_t b = lattice(lx + 1, key);
    const int32_t v = a + int32_t((int64_t(b - a) * frac) >> shift);
    sum += v >> octave;
  }
  return sum;
}

// Depth of the no-data border at position t along an edge: noise plus a slant, so the valid
// region looks like a slightly rotated, ragged scan or satellite swath.
uint32_t SyntheticGenerator::footprintDepth(uint32_t t, uint32_t side, uint32_t margin,
                                            uint32_t seed, bool slant_up) const {
  // A cell's far corner can lie past the edge; it takes the edge's last depth.
  t = std::min(t, side - 1);
  const uint64_t noise = uint64_t(footprintNoise(t, side, seed) + 4096);
  const uint64_t slant = uint64_t(margin) * (slant_up ? side - 1 - t : t) / side;
  return uint32_t(((margin * noise) >> 13) + slant);
}

void SyntheticGenerator::interpolateRowFields(int32_t fy) {
  for (size_t i = 0; i < size_t(kFieldCount) * grid_cols_; ++i) {
    const int32_t top = grid_top_[i];
    row_slopes_[i] = grid_bottom_[i] - top;
    row_fields_[i] = top + ((row_slopes_[i] * fy) >> kGridShift);
  }
}

SyntheticGenerator::RowFootprint SyntheticGenerator::rowFootprint(uint32_t y) const {
  const uint32_t width = spec_.width_px;
  const uint32_t height = spec_.height_px;
  RowFootprint footprint;
  footprint.left = footprintDepth(y, height, margin_x_px_, footprint_seeds_[0], false);
  const uint32_t right = footprintDepth(y, height, margin_x_px_, footprint_seeds_[1], true);
  footprint.valid_end = width - std::min(width, right);
  footprint.near_top = y < 2 * margin_y_px_;
  footprint.near_bottom = height - 1 - y < 2 * margin_y_px_;
  return footprint;
}

void SyntheticGenerator::chunkElevation(uint32_t y, uint32_t x0, uint32_t count) {
  int32_t* elevation = elevation_.data();
  // Coarse elevation, plus one pixel past the chunk for the horizontal slope.
  const int32_t* coarse = rowField(kElevation);
  for (uint32_t i = 0; i <= count; ++i) {
    const uint32_t x = x0 + i;
    const uint32_t gx = x >> kGridShift;
    const int32_t fx = int32_t(x & (kGridPx - 1));
    elevation[i] = coarse[gx] + (((coarse[gx + 1] - coarse[gx]) * fx) >> kGridShift);
  }
  for (const Octave& octave : fine_) addFineOctave(octave, y, x0, count);
}

void SyntheticGenerator::addFineOctave(const Octave& octave, uint32_t y, uint32_t x0,
                                       uint32_t count) {
  // Bilinear per pixel between lattice values looked up in a noise table at a per-lattice-row
  // offset (a hash per lattice row instead of per lattice point).
  const int32_t* fine_noise = noise_table_.data();
  int32_t* elevation = elevation_.data();
  const int shift = octave.cell_shift;
  const uint32_t ly = y >> shift;
  const int32_t wy = int32_t(y & ((1u << shift) - 1));
  const uint32_t key0 = mix(ly ^ octave.seed);
  const int32_t amplitude = octave.amplitude;
  if (shift == 0) {
    for (uint32_t i = 0; i <= count; ++i) {
      elevation[i] += (fine_noise[(x0 + i + key0) & kNoiseMask] * amplitude) >> 11;
    }
    return;
  }
  const uint32_t key1 = mix((ly + 1) ^ octave.seed);
  const uint32_t lx0 = x0 >> shift;
  const uint32_t lattice_cols = ((x0 + count) >> shift) - lx0 + 2;
  int32_t* values = lattice_.data();
  for (uint32_t j = 0; j < lattice_cols; ++j) {
    const int32_t a = fine_noise[(lx0 + j + key0) & kNoiseMask];
    const int32_t b = fine_noise[(lx0 + j + key1) & kNoiseMask];
    values[j] = ((a + (((b - a) * wy) >> shift)) * amplitude) >> 11;
  }
  const uint32_t mask = (1u << shift) - 1;
  for (uint32_t i = 0; i <= count; ++i) {
    const uint32_t x = x0 + i;
    const uint32_t j = (x >> shift) - lx0;
    elevation[i] += values[j] + (((values[j + 1] - values[j]) * int32_t(x & mask)) >> shift);
  }
}

SyntheticGenerator::CellLines SyntheticGenerator::cellLines(uint32_t gx) const {
  struct LineStyle {
    Field field;
    int32_t half_width16;
  };
  static constexpr LineStyle kLines[] = {{kRiver, kRiverHalfWidth16},
                                         {kStream, kStreamHalfWidth16},
                                         {kHighway, kHighwayHalfWidth16},
                                         {kRoad, kRoadHalfWidth16}};
  // A line field is linear across the cell, so if both ends have one sign and are farther
  // from zero than the line's half-width, no pixel of the cell is on the line.
  CellLines lines;
  for (const LineStyle& line : kLines) {
    const int32_t* v = rowField(line.field);
    const int32_t a = v[gx], b = v[gx + 1];
    const int32_t slope = std::abs(b - a) + std::abs(rowSlopes(line.field)[gx]);
    const int32_t limit = line.half_width16 * slope;  // compared with |value| * 256
    const bool crosses = (a ^ b) < 0 || std::min(std::abs(a), std::abs(b)) * 256 < limit;
    if (!crosses) continue;
    lines.mask |= 1u << line.field;
    lines.value[line.field] = a * int32_t(kGridPx);  // value * 16, stepped per pixel
    lines.step[line.field] = b - a;
    lines.limit[line.field] = limit;
  }
  return lines;
}

SyntheticGenerator::CellBorders SyntheticGenerator::cellBorders(
    uint32_t cell_x, const RowFootprint& footprint) const {
  const uint32_t width = spec_.width_px;
  CellBorders borders;
  if (footprint.near_top) {
    borders.top0 = int32_t(footprintDepth(cell_x, width, margin_y_px_, footprint_seeds_[2], true));
    borders.top1 =
        int32_t(footprintDepth(cell_x + kGridPx, width, margin_y_px_, footprint_seeds_[2], true));
  }
  if (footprint.near_bottom) {
    borders.bottom0 =
        int32_t(footprintDepth(cell_x, width, margin_y_px_, footprint_seeds_[3], false));
    borders.bottom1 =
        int32_t(footprintDepth(cell_x + kGridPx, width, margin_y_px_, footprint_seeds_[3], false));
  }
  return borders;
}

void SyntheticGenerator::colourCell(uint32_t y, uint32_t x0, uint32_t cell_x, uint32_t cell_count,
                                    const RowFootprint& footprint, uint8_t* out) const {
  const uint32_t height = spec_.height_px;
  const uint32_t channels = spec_.channels;
  const uint32_t gx = cell_x >> kGridShift;
  const int32_t* elevation = elevation_.data();
  const CellBorders borders = cellBorders(cell_x, footprint);
  const CellLines lines = cellLines(gx);
  const int32_t wet = clampInt((rowField(kMoisture)[gx] + 1024) >> 3, 0, 256);
  const int32_t slope_y = rowSlopes(kElevation)[gx] >> kGridShift;

  for (uint32_t k = 0; k < cell_count; ++k) {
    const uint32_t x = cell_x + k;
    const uint32_t i = x - x0;
    uint8_t* pixel = out + size_t(x) * channels;
    bool valid = x >= footprint.left && x < footprint.valid_end;
    if (footprint.near_top) {
      valid = valid && int32_t(y) >= borders.top0 + (((borders.top1 - borders.top0) * int32_t(k)) >>
                                                     kGridShift);
    }
    if (footprint.near_bottom) {
      valid = valid && int32_t(height - 1 - y) >=
                           borders.bottom0 +
                               (((borders.bottom1 - borders.bottom0) * int32_t(k)) >> kGridShift);
    }
    uint8_t shaded[3];
    const uint8_t* colour = valid ? terrainColour(elevation[i], elevation[i + 1] - elevation[i],
                                                  slope_y, wet, lines, k, shaded)
                                  : kNoDataColour;
    pixel[0] = colour[0];
    pixel[1] = colour[1];
    pixel[2] = colour[2];
    if (channels == 4) pixel[3] = valid ? 255 : 0;
  }
}

const uint8_t* SyntheticGenerator::terrainColour(int32_t elevation, int32_t slope_x,
                                                 int32_t slope_y, int32_t wet,
                                                 const CellLines& lines, uint32_t k,
                                                 uint8_t* shaded) const {
  const int32_t relative = elevation - kSeaLevel;
  if (relative < kDeepSea) return kDeepSeaColour;
  const int32_t index = clampInt((relative - kPaletteMin) >> 5, 0, kPaletteSize - 1);
  // Moisture picks one of kWetLevels palettes, dithered by the elevation's low bits.
  const int32_t level = (wet + ((elevation >> 2) & 15)) >> 4;
  const uint8_t* base = palettes_.data() + (size_t(level) * kPaletteSize + size_t(index)) * 3;
  if (relative < 0) return base;
  const int32_t slope = slope_x + slope_y;
  const int32_t shade = clampInt(256 - ((slope * kShadeGain) >> 8), 176, 336);
  for (int c = 0; c < 3; ++c) shaded[c] = uint8_t(std::min(255, (base[c] * shade) >> 8));
  if (lines.mask == 0) return shaded;
  auto on = [&](Field f) {
    if (!(lines.mask & (1u << f))) return false;
    const int32_t value16 = lines.value[f] + lines.step[f] * int32_t(k);
    return std::abs(value16) * 16 < lines.limit[f];
  };
  const bool road_zone = relative >= kRoadMinElevation && relative < kRoadMaxElevation;
  if (road_zone && on(kHighway)) return kHighwayColour;
  if (relative < kRiverMaxElevation && on(kRiver)) return kRiverColour;
  if (relative < kRiverMaxElevation && wet > 128 && on(kStream)) return kStreamColour;
  if (road_zone && wet < 176 && on(kRoad)) return kRoadColour;
  return shaded;
}

void SyntheticGenerator::generateRow(uint32_t y, uint8_t* out) {
  const uint32_t width = spec_.width_px;
  ensureGridRows(y >> kGridShift);
  // Coarse fields interpolated down to this row, and their vertical change per 16 px.
  interpolateRowFields(int32_t(y & (kGridPx - 1)));
  // Valid pixels lie in [left, width - right) on this row, and below top(x) and above
  // height - bottom(x); only rows near the top and bottom edges evaluate those, per grid column.
  const RowFootprint footprint = rowFootprint(y);
  for (uint32_t x0 = 0; x0 < width; x0 += kChunkPx) {
    const uint32_t count = std::min(kChunkPx, width - x0);
    chunkElevation(y, x0, count);
    // Colour, one grid cell (16 px) at a time: within a cell every coarse field is linear in
    // x, so per-cell decisions (which lines can cross it, its moisture) are exact or nearly.
    for (uint32_t cell_x = x0; cell_x < x0 + count; cell_x += kGridPx)
      colourCell(y, x0, cell_x, std::min(kGridPx, x0 + count - cell_x), footprint, out);
  }
}

void SyntheticGenerator::generateRows(uint32_t first_row, uint32_t rows, std::span<uint8_t> out) {
  const size_t row_bytes = size_t(spec_.width_px) * spec_.channels;
  TESSERA_CHECK(first_row <= spec_.height_px && rows <= spec_.height_px - first_row)
      << "synthetic rows " << first_row << "+" << rows << " past height " << spec_.height_px;
  TESSERA_CHECK(out.size() >= rows * row_bytes) << "synthetic output span too small";
  for (uint32_t r = 0; r < rows; ++r) generateRow(first_row + r, out.data() + r * row_bytes);
}

namespace {

class SyntheticReader final : public BandReader {
 public:
  SyntheticReader(const SyntheticSpec& spec, const std::string& name) : generator_(spec) {
    info_.width_px = spec.width_px;
    info_.height_px = spec.height_px;
    info_.channels = spec.channels;
    info_.natural_band_rows = std::min(kBandRows, spec.height_px);
    // The generator's per-row fields and slopes (six of each), the grid row it computes and
    // its lattice: a few dozen ints per grid column.
    info_.buffer_bytes =
        uint64_t(32) * (spec.width_px / kGridPx + 2) * sizeof(int32_t) + (uint64_t(1) << 20);
    info_.format = "synthetic";
    info_.metadata["synthetic"] = {{"source", name}, {"seed", spec.seed}};
  }
  const SourceInfo& info() const override { return info_; }
  Result<void> readRows(uint32_t rows, std::span<uint8_t> out) override {
    TESSERA_CHECK(rows > 0 && rows <= info_.height_px - next_row_)
        << "synthetic: readRows(" << rows << ") at row " << next_row_;
    generator_.generateRows(next_row_, rows, out);
    next_row_ += rows;
    return {};
  }

 private:
  SyntheticGenerator generator_;
  SourceInfo info_;
  uint32_t next_row_ = 0;
};

}  // namespace

Result<std::unique_ptr<BandReader>> openSyntheticReader(const std::string& spec) {
  TESSERA_ASSIGN_OR_RETURN(const SyntheticSpec parsed, parseSyntheticSpec(spec));
  return std::unique_ptr<BandReader>(
      std::make_unique<SyntheticReader>(parsed, "synthetic:" + spec));
}

}  // namespace tessera::detail
