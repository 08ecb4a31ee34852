// The encode side of bc1 (libsquish) and bc7 (Tessera's own mode-6 encoder; docs/codecs.md).
#include <squish.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

#include <fmt/format.h>

#include "bc/bc.h"
#include "codec_internal.h"

namespace tessera::detail {

namespace {

constexpr uint32_t kWeights4[16] = {0, 4, 9, 13, 17, 21, 26, 30, 34, 38, 43, 47, 51, 55, 60, 64};

using Texel = std::array<float, 4>;

/// One mode-6 candidate: 7-bit endpoints, their p-bits, the 16 indices and the error.
struct Mode6Block {
  uint32_t endpoint[2][4] = {};
  uint32_t p_bit[2] = {};
  uint8_t index[16] = {};
  float error = 0;
};

/// The 8-bit value of a 7-bit endpoint channel with its p-bit.
uint32_t endpointValue(const Mode6Block& block, uint32_t e, uint32_t channel) {
  return block.endpoint[e][channel] << 1 | block.p_bit[e];
}

/// Quantizes an endpoint to 7 bits per channel plus a shared p-bit, the p-bit given (0, 1) or
/// chosen for the least weighted error (-1).
void quantizeEndpoint(const Texel& value, const Texel& weight, int forced_p, Mode6Block& block,
                      uint32_t e) {
  float best_error = INFINITY;
  for (uint32_t p = 0; p < 2; ++p) {
    if (forced_p >= 0 && uint32_t(forced_p) != p) continue;
    float error = 0;
    uint32_t q[4];
    for (uint32_t c = 0; c < 4; ++c) {
      q[c] = uint32_t(std::clamp(std::lround((value[c] - float(p)) / 2.0f), 0L, 127L));
      const float d = float(q[c] << 1 | p) - value[c];
      error += weight[c] * d * d;
    }
    if (error < best_error) {
      best_error = error;
      block.p_bit[e] = p;
      std::memcpy(block.endpoint[e], q, sizeof q);
    }
  }
}

/// Picks each texel's nearest palette entry and sums the weighted error.
void assignIndices(const Texel* texels, const Texel& weight, Mode6Block& block) {
  float palette[16][4];
  for (uint32_t i = 0; i < 16; ++i)
    for (uint32_t c = 0; c < 4; ++c)
      palette[i][c] = float(((64 - kWeights4[i]) * endpointValue(block, 0, c) +
                             kWeights4[i] * endpointValue(block, 1, c) + 32) >>
                            6);
  block.error = 0;
  for (uint32_t t = 0; t < 16; ++t) {
    float best = INFINITY;
    for (uint32_t i = 0; i < 16; ++i) {
      float error = 0;
      for (uint32_t c = 0; c < 4; ++c) {
        const float d = palette[i][c] - texels[t][c];
        error += weight[c] * d * d;
      }
      if (error < best) {
        best = error;
        block.index[t] = uint8_t(i);
      }
    }
    block.error += best;
  }
}

/// The block's principal axis (power iteration on the weighted covariance) and mean.
void principalAxis(const Texel* texels, const Texel& weight, Texel& mean, Texel& axis) {
  mean = {};
  for (uint32_t t = 0; t < 16; ++t)
    for (uint32_t c = 0; c < 4; ++c) mean[c] += texels[t][c] / 16.0f;
  float covariance[4][4] = {};
  for (uint32_t t = 0; t < 16; ++t)
    for (uint32_t a = 0; a < 4; ++a)
      for (uint32_t b = 0; b < 4; ++b)
        covariance[a][b] +=
            std::sqrt(weight[a] * weight[b]) * (texels[t][a] - mean[a]) * (texels[t][b] - mean[b]);
  axis = {1, 1, 1, 1};
  for (int iteration = 0; iteration < 8; ++iteration) {
    Texel next{};
    for (uint32_t a = 0; a < 4; ++a)
      for (uint32_t b = 0; b < 4; ++b) next[a] += covariance[a][b] * axis[b];
    const float length =
        std::sqrt(next[0] * next[0] + next[1] * next[1] + next[2] * next[2] + next[3] * next[3]);
    if (length < 1e-6f) break;
    for (uint32_t c = 0; c < 4; ++c) axis[c] = next[c] / length;
  }
}

/// Endpoints that fit the chosen indices best in the least-squares sense; false when the
/// indices do not determine them (all texels on one index).
bool refitEndpoints(const Texel* texels, const Mode6Block& block, Texel& e0, Texel& e1) {
  float aa = 0, ab = 0, bb = 0;
  Texel ax{}, bx{};
  for (uint32_t t = 0; t < 16; ++t) {
    const float b = float(kWeights4[block.index[t]]) / 64.0f, a = 1.0f - b;
    aa += a * a, ab += a * b, bb += b * b;
    for (uint32_t c = 0; c < 4; ++c) ax[c] += a * texels[t][c], bx[c] += b * texels[t][c];
  }
  const float determinant = aa * bb - ab * ab;
  if (std::fabs(determinant) < 1e-6f) return false;
  for (uint32_t c = 0; c < 4; ++c) {
    e0[c] = std::clamp((bb * ax[c] - ab * bx[c]) / determinant, 0.0f, 255.0f);
    e1[c] = std::clamp((aa * bx[c] - ab * ax[c]) / determinant, 0.0f, 255.0f);
  }
  return true;
}

Mode6Block fitEndpoints(const Texel* texels, const Texel& weight, Texel e0, Texel e1, int passes,
                        bool try_all_p_bits) {
  Mode6Block best;
  best.error = INFINITY;
  for (int pass = 0; pass <= passes; ++pass) {
    for (int p = try_all_p_bits ? 0 : -1; p < (try_all_p_bits ? 4 : 0); ++p) {
      Mode6Block candidate;
      quantizeEndpoint(e0, weight, p < 0 ? -1 : p & 1, candidate, 0);
      quantizeEndpoint(e1, weight, p < 0 ? -1 : p >> 1, candidate, 1);
      assignIndices(texels, weight, candidate);
      if (candidate.error < best.error) best = candidate;
    }
    if (pass == passes || !refitEndpoints(texels, best, e0, e1)) break;
  }
  return best;
}

void packMode6(Mode6Block block, uint8_t* out) {
  // The anchor texel's index loses its top bit: flip the endpoints so that it is zero.
  if (block.index[0] >= 8) {
    std::swap(block.endpoint[0], block.endpoint[1]);
    std::swap(block.p_bit[0], block.p_bit[1]);
    for (uint8_t& index : block.index) index = uint8_t(15 - index);
  }
  std::memset(out, 0, 16);
  uint32_t position = 0;
  const auto put = [&](uint32_t value, uint32_t count) {
    for (uint32_t i = 0; i < count; ++i, ++position)
      out[position >> 3] |= uint8_t(((value >> i) & 1) << (position & 7));
  };
  put(1u << 6, 7);
  for (uint32_t c = 0; c < 4; ++c)
    for (uint32_t e = 0; e < 2; ++e) put(block.endpoint[e][c], 7);
  put(block.p_bit[0], 1);
  put(block.p_bit[1], 1);
  for (uint32_t t = 0; t < 16; ++t) put(block.index[t], t == 0 ? 3 : 4);
}

void encodeBc7Block(const uint8_t* rgba, bool alpha_matters, int effort, uint8_t* out) {
  Texel texels[16];
  for (uint32_t t = 0; t < 16; ++t)
    for (uint32_t c = 0; c < 4; ++c) texels[t][c] = float(rgba[4 * t + c]);
  // Without an alpha channel the decoded alpha is dropped, so it costs nothing to miss it.
  const Texel weight = {1, 1, 1, alpha_matters ? 1.0f : 0.0f};
  Texel mean, axis;
  principalAxis(texels, weight, mean, axis);
  float low = INFINITY, high = -INFINITY;
  for (uint32_t t = 0; t < 16; ++t) {
    float projection = 0;
    for (uint32_t c = 0; c < 4; ++c) projection += (texels[t][c] - mean[c]) * axis[c];
    low = std::min(low, projection), high = std::max(high, projection);
  }
  Texel e0, e1;
  for (uint32_t c = 0; c < 4; ++c) {
    e0[c] = std::clamp(mean[c] + low * axis[c], 0.0f, 255.0f);
    e1[c] = std::clamp(mean[c] + high * axis[c], 0.0f, 255.0f);
  }
  packMode6(fitEndpoints(texels, weight, e0, e1, effort, effort >= 3), out);
}

Result<void> checkEightBit(Codec codec, const ImageView& tile) {
  if (tile.sample_type == SampleType::kU8) return {};
  return fail(ErrorCode::kUnsupported,
              fmt::format("{} stores 8-bit samples only, not {}", codecName(codec),
                          sampleTypeName(tile.sample_type)));
}

/// The payload of `tile`: `encode_block(rgba, block)` writes each block from its 16 texels.
template <class EncodeBlock>
std::vector<uint8_t> encodeBlocks(Codec codec, const ImageView& tile, EncodeBlock encode_block) {
  std::vector<uint8_t> payload(bcPayloadBytes(codec, tile.width_px, tile.height_px));
  const uint32_t blocks_x = bcBlocksAlong(tile.width_px), blocks_y = bcBlocksAlong(tile.height_px);
  uint8_t rgba[64];
  uint8_t* block = payload.data();
  for (uint32_t by = 0; by < blocks_y; ++by)
    for (uint32_t bx = 0; bx < blocks_x; ++bx, block += bcBlockBytes(codec)) {
      gatherBlockRgba(tile, bx, by, rgba);
      encode_block(rgba, block);
    }
  return payload;
}

}  // namespace

void gatherBlockRgba(const ImageView& tile, uint32_t block_x, uint32_t block_y, uint8_t* rgba) {
  for (uint32_t y = 0; y < kBcBlockSidePx; ++y) {
    const uint32_t py = std::min(block_y * kBcBlockSidePx + y, tile.height_px - 1);
    for (uint32_t x = 0; x < kBcBlockSidePx; ++x) {
      const uint32_t px = std::min(block_x * kBcBlockSidePx + x, tile.width_px - 1);
      const uint8_t* src = tile.row(py) + size_t(px) * tile.channels;
      uint8_t* dst = rgba + 4 * (y * kBcBlockSidePx + x);
      switch (tile.channels) {
        case 1: dst[0] = dst[1] = dst[2] = src[0], dst[3] = 255; break;
        case 2: dst[0] = dst[1] = dst[2] = src[0], dst[3] = src[1]; break;
        case 3: std::memcpy(dst, src, 3), dst[3] = 255; break;
        default: std::memcpy(dst, src, 4); break;
      }
    }
  }
}

Result<std::vector<uint8_t>> encodeBc1(const ImageView& tile, const EncodeOptions& options,
                                       const ParentTexels*, CodecScratch*) {
  TESSERA_TRY(checkEightBit(Codec::kBc1, tile));
  if (tile.channels == 2 || tile.channels == 4)
    return fail(ErrorCode::kUnsupported,
                fmt::format("bc1 keeps no alpha channel; this tile has {} channels (use bc7)",
                            tile.channels));
  const int fit = options.effort == 1   ? squish::kColourRangeFit
                  : options.effort >= 3 ? squish::kColourIterativeClusterFit
                                        : squish::kColourClusterFit;
  return encodeBlocks(Codec::kBc1, tile, [fit](const uint8_t* rgba, uint8_t* block) {
    squish::Compress(rgba, block, squish::kDxt1 | fit);
  });
}

Result<std::vector<uint8_t>> encodeBc7(const ImageView& tile, const EncodeOptions& options,
                                       const ParentTexels*, CodecScratch*) {
  TESSERA_TRY(checkEightBit(Codec::kBc7, tile));
  const int effort = options.effort == 0 ? 1 : std::clamp(options.effort, 1, 4);
  const bool alpha_matters = tile.channels == 2 || tile.channels == 4;
  return encodeBlocks(Codec::kBc7, tile, [=](const uint8_t* rgba, uint8_t* block) {
    encodeBc7Block(rgba, alpha_matters, effort, block);
  });
}

}  // namespace tessera::detail
