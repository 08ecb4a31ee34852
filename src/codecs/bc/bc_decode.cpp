#include <algorithm>
#include <cstring>

#include <fmt/format.h>

#include "bc/bc.h"
#include "codec_internal.h"

namespace tessera::detail {

namespace {

struct Rgb {
  uint32_t r, g, b;
};

// 5- and 6-bit channels widened by repeating their top bits, as the GPUs do.
Rgb expand565(uint16_t packed) {
  const uint32_t r = (packed >> 11) & 31, g = (packed >> 5) & 63, b = packed & 31;
  return {(r << 3) | (r >> 2), (g << 2) | (g >> 4), (b << 3) | (b >> 2)};
}

/// Reads the bits of a 128-bit BC7 block from the least significant end.
class BitReader {
 public:
  explicit BitReader(const uint8_t* block) { std::memcpy(bytes_, block, 16); }
  uint32_t take(uint32_t count) {
    uint32_t value = 0;
    for (uint32_t i = 0; i < count; ++i, ++position_)
      value |= uint32_t((bytes_[position_ >> 3] >> (position_ & 7)) & 1) << i;
    return value;
  }

 private:
  uint8_t bytes_[16];
  uint32_t position_ = 0;
};

// The 4-bit index weights of the BC7 specification, in 64ths.
constexpr uint32_t kWeights4[16] = {0, 4, 9, 13, 17, 21, 26, 30, 34, 38, 43, 47, 51, 55, 60, 64};

/// Copies the decoded 4x4 blocks' channels into `out`, dropping what the padding added.
void scatterBlock(const uint8_t* rgba, uint32_t block_x, uint32_t block_y, Image& out) {
  const uint32_t channels = out.channels;
  for (uint32_t y = 0; y < kBcBlockSidePx; ++y) {
    const uint32_t py = block_y * kBcBlockSidePx + y;
    if (py >= out.height_px) break;
    for (uint32_t x = 0; x < kBcBlockSidePx; ++x) {
      const uint32_t px = block_x * kBcBlockSidePx + x;
      if (px >= out.width_px) break;
      const uint8_t* texel = rgba + 4 * (y * kBcBlockSidePx + x);
      uint8_t* dst = out.texels.data() + (size_t(py) * out.width_px + px) * channels;
      // Grey images keep red; grey with alpha keeps red and alpha (bc.h, gatherBlockRgba).
      if (channels <= 2) {
        dst[0] = texel[0];
        if (channels == 2) dst[1] = texel[3];
      } else {
        std::memcpy(dst, texel, channels);
      }
    }
  }
}

Result<void> decodeBlocks(Codec codec, std::span<const uint8_t> payload, Image& out) {
  const size_t expected = bcPayloadBytes(codec, out.width_px, out.height_px);
  if (payload.size() != expected)
    return fail(
        ErrorCode::kCorrupt,
        fmt::format("{} payload: {} bytes, {} expected for {} (4x4 blocks of {} bytes)",
                    codecName(codec), payload.size(), expected,
                    geometryText(out.width_px, out.height_px, out.channels), bcBlockBytes(codec)));
  const uint32_t blocks_x = bcBlocksAlong(out.width_px), blocks_y = bcBlocksAlong(out.height_px);
  uint8_t rgba[64];
  const uint8_t* block = payload.data();
  for (uint32_t by = 0; by < blocks_y; ++by) {
    for (uint32_t bx = 0; bx < blocks_x; ++bx, block += bcBlockBytes(codec)) {
      if (codec == Codec::kBc1) {
        decodeBc1Block(block, rgba);
      } else if (const int mode = decodeBc7Block(block, rgba); mode < 0) {
        return fail(ErrorCode::kUnsupported,
                    fmt::format("bc7 payload: block ({}, {}) has mode byte 0x{:02x}; this "
                                "decoder reads mode 6 only (docs/codecs.md)",
                                bx, by, block[0]));
      }
      scatterBlock(rgba, bx, by, out);
    }
  }
  return {};
}

}  // namespace

void decodeBc1Block(const uint8_t* block, uint8_t* rgba) {
  const uint16_t packed0 = uint16_t(block[0] | block[1] << 8);
  const uint16_t packed1 = uint16_t(block[2] | block[3] << 8);
  const Rgb c0 = expand565(packed0), c1 = expand565(packed1);
  uint8_t palette[4][4] = {{uint8_t(c0.r), uint8_t(c0.g), uint8_t(c0.b), 255},
                           {uint8_t(c1.r), uint8_t(c1.g), uint8_t(c1.b), 255}};
  if (packed0 > packed1) {
    palette[2][0] = uint8_t((2 * c0.r + c1.r) / 3);
    palette[2][1] = uint8_t((2 * c0.g + c1.g) / 3);
    palette[2][2] = uint8_t((2 * c0.b + c1.b) / 3);
    palette[3][0] = uint8_t((c0.r + 2 * c1.r) / 3);
    palette[3][1] = uint8_t((c0.g + 2 * c1.g) / 3);
    palette[3][2] = uint8_t((c0.b + 2 * c1.b) / 3);
    palette[2][3] = palette[3][3] = 255;
  } else {
    // Three colours and transparent black (the punch-through mode).
    palette[2][0] = uint8_t((c0.r + c1.r) / 2);
    palette[2][1] = uint8_t((c0.g + c1.g) / 2);
    palette[2][2] = uint8_t((c0.b + c1.b) / 2);
    palette[2][3] = 255;
  }
  const uint32_t indices = uint32_t(block[4]) | uint32_t(block[5]) << 8 | uint32_t(block[6]) << 16 |
                           uint32_t(block[7]) << 24;
  for (uint32_t i = 0; i < 16; ++i) std::memcpy(rgba + 4 * i, palette[(indices >> (2 * i)) & 3], 4);
}

int decodeBc7Block(const uint8_t* block, uint8_t* rgba) {
  // Mode 6 is the byte 0b1000000 in the low bits: six zero bits, then a one.
  if ((block[0] & 0x7f) != 0x40) return -1;
  BitReader bits(block);
  bits.take(7);
  uint32_t endpoint[2][4];
  for (uint32_t channel = 0; channel < 4; ++channel)
    for (uint32_t e = 0; e < 2; ++e) endpoint[e][channel] = bits.take(7) << 1;
  for (uint32_t e = 0; e < 2; ++e) {
    const uint32_t p_bit = bits.take(1);
    for (uint32_t channel = 0; channel < 4; ++channel) endpoint[e][channel] |= p_bit;
  }
  for (uint32_t i = 0; i < 16; ++i) {
    // The anchor (texel 0) drops its index's top bit, which the encoder keeps at zero.
    const uint32_t index = bits.take(i == 0 ? 3 : 4);
    const uint32_t weight = kWeights4[index];
    for (uint32_t channel = 0; channel < 4; ++channel)
      rgba[4 * i + channel] =
          uint8_t(((64 - weight) * endpoint[0][channel] + weight * endpoint[1][channel] + 32) >> 6);
  }
  return 6;
}

Result<void> decodeBc1(std::span<const uint8_t> payload, Image& out, const ParentTexels*,
                       CodecScratch*) {
  return decodeBlocks(Codec::kBc1, payload, out);
}

Result<void> decodeBc7(std::span<const uint8_t> payload, Image& out, const ParentTexels*,
                       CodecScratch*) {
  return decodeBlocks(Codec::kBc7, payload, out);
}

}  // namespace tessera::detail
