// The fast BC1 encoder (bc1_fast.h; docs/codecs.md, "Fast bc1 transcoder"). Per block: the
// principal axis of the texels (power iteration on their covariance), endpoints at the
// extreme projections on it pulled in by 1/16 of their span (the inset of van Waveren's
// "Real-Time DXT Compression", 2006: extremes are often outliers the palette need not reach),
// rounded to 565, and each texel's 2-bit index by rounding its position along the axis (for
// four evenly spaced colours on a line that is the nearest colour). A least-squares refit of the
// endpoints to those indices gained 0.4 dB on real imagery for about 30 % more time, which a
// load-time transcode cannot spend.
//
// Four blocks are encoded together, one per lane of a vector, so that every step is SIMD
// arithmetic (SSE2 on x86-64) with no reduction across lanes and no branch per block; flat
// blocks alone are rewritten afterwards, one at a time.
#include "codecs/bc1_fast.h"

#include <algorithm>
#include <bit>
#include <cstdlib>
#include <cstring>
#include <iterator>

#include <fmt/format.h>

#include "bc/bc.h"
#include "codec_internal.h"

namespace tessera::detail {

namespace {

constexpr uint32_t kTexels = 16;
/// Blocks encoded together, one per lane of a 16-byte vector (SSE2 on x86-64, NEON on Arm).
constexpr uint32_t kLanes = 4;
/// Power iterations after the start (a covariance column, itself one step): a 4x4 block's
/// colours are usually far from isotropic, so the axis settles at once (a second step gained
/// 0.01 dB on real imagery), and where they are isotropic any axis does as well.
constexpr int kPowerIterations = 1;
constexpr float kInset = 1.0f / 16.0f;

// GCC's vector extensions: each operator works on all lanes, and a comparison gives -1 (true)
// or 0 per lane, which `?:` takes as a per-lane choice.
using F4 = float __attribute__((vector_size(16)));
using I4 = int32_t __attribute__((vector_size(16)));

F4 splat(float value) {
  return F4{value, value, value, value};
}
#if defined(__SSE__)
// One instruction each, where the portable form below takes a compare and three logic ops.
F4 vmin(F4 a, F4 b) {
  return __builtin_ia32_minps(a, b);
}
F4 vmax(F4 a, F4 b) {
  return __builtin_ia32_maxps(a, b);
}
#else
F4 vmin(F4 a, F4 b) {
  return a < b ? a : b;
}
F4 vmax(F4 a, F4 b) {
  return a > b ? a : b;
}
#endif
F4 vabs(F4 a) {
  return a < 0 ? -a : a;
}
F4 vclamp(F4 a) {
  return vmin(vmax(a, splat(0)), splat(255));
}

/// Four blocks' texels, channel-planar, a lane per block.
struct BlockGroup {
  F4 texel[3][kTexels];
  uint32_t lanes = 0;  ///< blocks in use (1..kLanes); the others repeat the last one
};

/// Two endpoints per block in 8-bit units, before quantisation, and each texel's position on
/// the axis between them.
struct Endpoints {
  F4 a[3];
  F4 b[3];
  F4 position[kTexels];  ///< texel dotted with the axis over its squared length
  F4 position_a;         ///< the same for endpoint a; b's is larger unless the block is flat
  F4 position_b;
};

/// A group's BC1 fields: the endpoints quantised to 565 in the four-colour order (colour0
/// above colour1), and the 16 2-bit indices, texel 0 in the low bits.
struct Fit {
  I4 colour0;
  I4 colour1;
  I4 indices;
};

/// An endpoint channel of `bits` bits (5 or 6) widened to 8 as the decoder does (bc_decode.cpp).
constexpr int widen(int value, int bits) {
  return bits == 5 ? (value << 3 | value >> 2) : (value << 2 | value >> 4);
}

/// For each 8-bit value, two endpoint channels whose palette entry 2, (2 * first + second) / 3
/// once widened, comes nearest to it: a flat block becomes that one palette colour, within a
/// level of its texels, where rounding each endpoint to 565 would miss by up to 4.
struct FlatFit {
  uint8_t first[256];
  uint8_t second[256];
};

FlatFit makeFlatFit(int bits) {
  FlatFit fit{};
  int best[256];
  std::fill(std::begin(best), std::end(best), 1 << 30);
  const int levels = 1 << bits;
  // Each pair is scored against the values near its colour only: every value has a pair
  // within a level of it (the tests check), so the nearest is always among those.
  for (int a = 0; a < levels; ++a)
    for (int b = 0; b < levels; ++b) {
      const int wa = widen(a, bits), wb = widen(b, bits), colour = (2 * wa + wb) / 3;
      for (int value = std::max(0, colour - 4); value <= std::min(255, colour + 4); ++value) {
        // A narrow pair breaks ties: GPUs round the thirds a little differently, and the
        // narrower the pair, the less that moves the colour.
        const int cost = std::abs(colour - value) * 1024 + std::abs(wa - wb);
        if (cost < best[value])
          best[value] = cost, fit.first[value] = uint8_t(a), fit.second[value] = uint8_t(b);
      }
    }
  return fit;
}

void writeBlock(uint32_t colour0, uint32_t colour1, uint32_t indices, uint8_t* out) {
  const uint8_t bytes[8] = {uint8_t(colour0),       uint8_t(colour0 >> 8), uint8_t(colour1),
                            uint8_t(colour1 >> 8),  uint8_t(indices),      uint8_t(indices >> 8),
                            uint8_t(indices >> 16), uint8_t(indices >> 24)};
  std::memcpy(out, bytes, 8);
}

void encodeFlatBlock(const int rgb[3], uint8_t* out) {
  static const FlatFit fit5 = makeFlatFit(5), fit6 = makeFlatFit(6);
  uint32_t colour0 = 0, colour1 = 0;
  for (int c = 0; c < 3; ++c) {
    const FlatFit& fit = c == 1 ? fit6 : fit5;
    const int shift = c == 0 ? 11 : c == 1 ? 5 : 0;
    colour0 |= uint32_t(fit.first[rgb[c]]) << shift;
    colour1 |= uint32_t(fit.second[rgb[c]]) << shift;
  }
  // Every texel takes palette entry 2 (index bits 10); with the endpoints swapped into the
  // four-colour order the same colour is entry 3; equal endpoints are the colour itself.
  if (colour0 == colour1)
    writeBlock(colour0, colour1, 0, out);
  else if (colour0 > colour1)
    writeBlock(colour0, colour1, 0xaaaaaaaau, out);
  else
    writeBlock(colour1, colour0, 0xffffffffu, out);
}

/// Loads the blocks (first_block_x .. + group.lanes - 1, block_y) of `tile`, texels past its
/// edge repeating the last column and row, lanes past `group.lanes` repeating the last block.
template <uint32_t kChannels>
void gatherGroup(const ImageView& tile, uint32_t first_block_x, uint32_t block_y,
                 BlockGroup& group) {
  alignas(16) int32_t values[3][kTexels][kLanes];
  const uint32_t x0 = first_block_x * kBcBlockSidePx, y0 = block_y * kBcBlockSidePx;
  const bool inside = group.lanes == kLanes && x0 + kLanes * kBcBlockSidePx <= tile.width_px &&
                      y0 + kBcBlockSidePx <= tile.height_px;
  // The word reads below take a byte past an RGB texel: not past the tile's last one.
  const bool ends_tile =
      x0 + kLanes * kBcBlockSidePx == tile.width_px && y0 + kBcBlockSidePx == tile.height_px;
  if (inside && !(kChannels == 3 && ends_tile)) {
    // Most groups: four rows of 16 texels, at offsets the compiler knows, each vector built
    // from its four bytes in registers (a byte array read back as a vector would stall on
    // store forwarding).
    for (uint32_t y = 0; y < kBcBlockSidePx; ++y) {
      const uint8_t* row = tile.row(y0 + y) + size_t(x0) * kChannels;
      constexpr uint32_t kLaneBytes = kBcBlockSidePx * kChannels;
      for (uint32_t x = 0; x < kBcBlockSidePx; ++x) {
        const uint32_t t = y * kBcBlockSidePx + x;
        const uint8_t* src = row + x * kChannels;
        if constexpr (kChannels >= 3 && std::endian::native == std::endian::little) {
          // A texel's bytes read as one little-endian word per lane and split by shifts. For
          // RGB, lanes are 12 bytes apart: one 16-byte read holds two lanes' words, at its
          // first and last word.
          I4 w;
          if constexpr (kChannels == 3) {
            I4 low, high;
            std::memcpy(&low, src, 16);
            std::memcpy(&high, src + 2 * kLaneBytes, 16);
            w = __builtin_shufflevector(low, high, 0, 3, 4, 7);
          } else {
            uint32_t words[kLanes];
            for (uint32_t lane = 0; lane < kLanes; ++lane)
              std::memcpy(&words[lane], src + lane * kLaneBytes, 4);
            w = I4{int32_t(words[0]), int32_t(words[1]), int32_t(words[2]), int32_t(words[3])};
          }
          group.texel[0][t] = __builtin_convertvector(w & 0xff, F4);
          group.texel[1][t] = __builtin_convertvector((w >> 8) & 0xff, F4);
          group.texel[2][t] = __builtin_convertvector((w >> 16) & 0xff, F4);
        } else {
          for (uint32_t c = 0; c < 3; ++c) {
            const uint8_t* channel = src + (kChannels >= 3 ? c : 0);
            const I4 v = {channel[0], channel[kLaneBytes], channel[2 * kLaneBytes],
                          channel[3 * kLaneBytes]};
            group.texel[c][t] = __builtin_convertvector(v, F4);
          }
        }
      }
    }
    return;
  }
  {
    for (uint32_t y = 0; y < kBcBlockSidePx; ++y) {
      const uint8_t* row = tile.row(std::min(y0 + y, tile.height_px - 1));
      for (uint32_t lane = 0; lane < kLanes; ++lane) {
        const uint32_t block_x = first_block_x + std::min(lane, group.lanes - 1);
        for (uint32_t x = 0; x < kBcBlockSidePx; ++x) {
          const uint32_t px = std::min(block_x * kBcBlockSidePx + x, tile.width_px - 1);
          const uint8_t* src = row + size_t(px) * kChannels;
          for (uint32_t c = 0; c < 3; ++c)
            values[c][y * kBcBlockSidePx + x][lane] = src[kChannels >= 3 ? c : 0];
        }
      }
    }
  }
  for (uint32_t c = 0; c < 3; ++c)
    for (uint32_t t = 0; t < kTexels; ++t) {
      I4 v;
      std::memcpy(&v, values[c][t], sizeof v);
      group.texel[c][t] = __builtin_convertvector(v, F4);
    }
}

/// The endpoints on each block's principal axis, inset; `flat` marks one-colour blocks.
void findEndpoints(const BlockGroup& group, Endpoints& ends, I4& flat) {
  // Sums of the texels and of their products (rr, gg, bb, rg, rb, gb), then the covariance
  // from them: all exact, as the texels are integers, every sum stays below 2^24, and so does
  // every product of two channel sums, of which the mean terms are a sixteenth.
  F4 sum[3] = {}, cov[6] = {};
  for (uint32_t t = 0; t < kTexels; ++t) {
    const F4 r = group.texel[0][t], g = group.texel[1][t], b = group.texel[2][t];
    sum[0] += r, sum[1] += g, sum[2] += b;
    cov[0] += r * r, cov[1] += g * g, cov[2] += b * b;
    cov[3] += r * g, cov[4] += r * b, cov[5] += g * b;
  }
  const F4 mean[3] = {sum[0] * (1.0f / kTexels), sum[1] * (1.0f / kTexels),
                      sum[2] * (1.0f / kTexels)};
  cov[0] -= sum[0] * mean[0], cov[1] -= sum[1] * mean[1], cov[2] -= sum[2] * mean[2];
  cov[3] -= sum[0] * mean[1], cov[4] -= sum[0] * mean[2], cov[5] -= sum[1] * mean[2];
  // The variances' sum is 0 exactly for a flat block and at least 15/16 otherwise.
  flat = cov[0] + cov[1] + cov[2] == 0;
  // Power iteration from the covariance's column of the channel that varies most (already one
  // step from any start). The floats stay in range unscaled: the start is below 2^20 and each
  // step multiplies by less than 2^22, far from float's 2^128 for a few steps.
  const I4 red_most = (cov[0] >= cov[1]) & (cov[0] >= cov[2]);
  const I4 green_most = ~red_most & (cov[1] >= cov[2]);
  F4 x = red_most ? cov[0] : green_most ? cov[3] : cov[4];
  F4 y = red_most ? cov[3] : green_most ? cov[1] : cov[5];
  F4 z = red_most ? cov[4] : green_most ? cov[5] : cov[2];
  for (int i = 0; i < kPowerIterations; ++i) {
    const F4 nx = cov[0] * x + cov[3] * y + cov[4] * z;
    const F4 ny = cov[3] * x + cov[1] * y + cov[5] * z;
    const F4 nz = cov[4] * x + cov[5] * y + cov[2] * z;
    x = nx, y = ny, z = nz;
  }
  // Rescaled once so that the squared length below stays in range.
  const F4 scale = 1.0f / vmax(vmax(vabs(x), vabs(y)), vmax(vabs(z), splat(1e-30f)));
  x *= scale, y *= scale, z *= scale;
  // Flat blocks have no covariance; they are encoded apart, and any axis does here.
  const I4 degenerate = x * x + y * y + z * z < 1e-12f;
  x = degenerate ? splat(1) : x, y = degenerate ? splat(1) : y, z = degenerate ? splat(1) : z;
  const F4 axis[3] = {x, y, z};
  // The axis over its squared length: a texel's offset from the mean dotted with it is its
  // position along the axis in axis lengths.
  const F4 norm = 1.0f / (x * x + y * y + z * z);
  const F4 unit[3] = {x * norm, y * norm, z * norm};
  F4 low_s = splat(1e30f), high_s = splat(-1e30f);
  for (uint32_t t = 0; t < kTexels; ++t) {
    const F4 s =
        group.texel[0][t] * unit[0] + group.texel[1][t] * unit[1] + group.texel[2][t] * unit[2];
    low_s = vmin(low_s, s), high_s = vmax(high_s, s);
    ends.position[t] = s;
  }
  // Positions relative to the mean's.
  const F4 mean_s = mean[0] * unit[0] + mean[1] * unit[1] + mean[2] * unit[2];
  low_s -= mean_s, high_s -= mean_s;
  const F4 inset = (high_s - low_s) * kInset;
  low_s += inset, high_s -= inset;
  ends.position_a = low_s + mean_s, ends.position_b = high_s + mean_s;
  for (uint32_t c = 0; c < 3; ++c) {
    ends.a[c] = vclamp(mean[c] + low_s * axis[c]);
    ends.b[c] = vclamp(mean[c] + high_s * axis[c]);
  }
}

/// Quantises the endpoints to 565 and gives each texel the index of its position on the axis
/// (one pass less than projecting onto the quantised endpoints' line, for 0.2 dB).
void fitIndices(const Endpoints& ends, Fit& fit) {
  I4 packed_a = {}, packed_b = {};
  for (uint32_t c = 0; c < 3; ++c) {
    const int bits = c == 1 ? 6 : 5, shift = c == 0 ? 11 : c == 1 ? 5 : 0;
    const float levels = float((1 << bits) - 1) / 255.0f;
    // Endpoints are clamped to 0..255, so truncation after adding a half rounds.
    packed_a |= __builtin_convertvector(ends.a[c] * levels + 0.5f, I4) << shift;
    packed_b |= __builtin_convertvector(ends.b[c] * levels + 0.5f, I4) << shift;
  }
  // Four colours need colour0 > colour1: where a is the smaller, b is colour0 and the steps
  // run from b's end of the axis.
  const I4 swap = packed_a < packed_b;
  fit.colour0 = swap ? packed_b : packed_a, fit.colour1 = swap ? packed_a : packed_b;
  const F4 span = ends.position_b - ends.position_a;
  const F4 scale = span > 0 ? 3.0f / vmax(span, splat(1e-6f)) : splat(0);
  const F4 origin = swap ? ends.position_b : ends.position_a;
  const F4 step_scale = swap ? -scale : scale;
  I4 indices = {};
  for (uint32_t t = 0; t < kTexels; ++t) {
    // `s` runs from 0 at colour0 to 3 at colour1; the nearest of steps 0, 1, 2, 3 is index 0,
    // 2, 3, 1: the low bit from step 2 on, the high bit at steps 1 and 2.
    const F4 s = (ends.position[t] - origin) * step_scale;
    const I4 low_bit = s >= 1.5f, high_bit = (s >= 0.5f) & (s < 2.5f);
    indices |= ((low_bit & 1) | (high_bit & 2)) << (2 * t);
  }
  // Equal colours (a flat block's, or one that 565 made flat) take index 0.
  fit.indices = indices & (fit.colour0 != fit.colour1);
}

template <uint32_t kChannels>
void encodeTile(const ImageView& tile, uint8_t* payload) {
  const uint32_t blocks_x = bcBlocksAlong(tile.width_px), blocks_y = bcBlocksAlong(tile.height_px);
  BlockGroup group;
  Endpoints ends;
  Fit fit;
  I4 flat;
  for (uint32_t by = 0; by < blocks_y; ++by)
    for (uint32_t bx = 0; bx < blocks_x; bx += kLanes) {
      group.lanes = std::min(kLanes, blocks_x - bx);
      gatherGroup<kChannels>(tile, bx, by, group);
      findEndpoints(group, ends, flat);
      fitIndices(ends, fit);
      for (uint32_t l = 0; l < group.lanes; ++l) {
        uint8_t* out = payload + (size_t(by) * blocks_x + bx + l) * 8;
        if (flat[l]) {
          const int rgb[3] = {int(group.texel[0][0][l]), int(group.texel[1][0][l]),
                              int(group.texel[2][0][l])};
          encodeFlatBlock(rgb, out);
        } else {
          writeBlock(uint32_t(fit.colour0[l]), uint32_t(fit.colour1[l]), uint32_t(fit.indices[l]),
                     out);
        }
      }
    }
}

}  // namespace

Result<void> encodeBc1Fast(const ImageView& tile, std::span<uint8_t> payload) {
  const std::string what = geometryText(tile.width_px, tile.height_px, tile.channels);
  if (tile.sample_type != SampleType::kU8)
    return fail(ErrorCode::kUnsupported,
                fmt::format("bc1 transcode of a {} tile: {} samples, 8-bit only", what,
                            sampleTypeName(tile.sample_type)));
  if (tile.width_px == 0 || tile.height_px == 0 || tile.channels == 0 || tile.channels > 4)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("bc1 transcode of a {} tile: needs at least 1x1 texels of 1..4 "
                            "channels",
                            what));
  const size_t bytes = bcPayloadBytes(Codec::kBc1, tile.width_px, tile.height_px);
  if (payload.size() < bytes)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("bc1 transcode of a {} tile: the payload buffer holds {} bytes, "
                            "{} needed",
                            what, payload.size(), bytes));
  switch (tile.channels) {
    case 1: encodeTile<1>(tile, payload.data()); break;
    case 2: encodeTile<2>(tile, payload.data()); break;
    case 3: encodeTile<3>(tile, payload.data()); break;
    default: encodeTile<4>(tile, payload.data()); break;
  }
  return {};
}

}  // namespace tessera::detail
