#pragma once
// The input layout of codec_fuzzer, shared with the seed-corpus generator so both agree:
//   byte 0: bits 0-2 the low bits of the codec, bits 3-4 channels - 1,
//           bit 5 mode (0: decode the payload, 1: encode the texels, decode, compare),
//           bits 6-7 ptm: the quarter of the parent the tile refines, in x and y; other
//           codecs: the sample type (0 u8, 1 u16, 2 f32, 3 u8)
//   byte 1: width - 1 (low 6 bits), bit 6 the codec's bit 3 (codec values 10..15, which do
//           not exist, fold back to 2..7); byte 2: height - 1 (low 6 bits): tiles up to 64x64
//           keep each run fast, and the codecs' size-dependent paths are all reached below that
//   decode mode: bytes 3.. are the payload
//   round-trip mode: byte 3 JPEG quality (1 + b % 100), byte 4 bits 0-3 effort (0..9),
//           bit 4 chroma subsampling; bytes 5.. are texels, repeated to fill the tile
// ptm gets a parent (fuzzParentTexels) for square tiles of even side.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "codecs/decode.h"

namespace tessera::fuzz {

inline constexpr size_t kCodecFuzzHeaderBytes = 3;
inline constexpr uint32_t kCodecFuzzMaxSidePx = 64;

struct CodecFuzzInput {
  Codec codec;
  uint32_t channels;
  SampleType sample_type;  ///< u8 for ptm
  bool round_trip;
  uint32_t width_px;
  uint32_t height_px;
  std::span<const uint8_t> rest;  ///< payload, or options + texels in round-trip mode
  uint32_t quadrant_x;            ///< ptm: the parent's quarter the tile refines
  uint32_t quadrant_y;
};

/// The parent a ptm tile of `side` x `side` (even, no border) is coded against: a fixed texel
/// pattern of the same geometry, so corpus files made by the generator decode in the fuzzer.
inline Image fuzzParentTexels(uint32_t side, uint32_t channels) {
  Image parent(side, side, channels);
  for (size_t i = 0; i < parent.texels.size(); ++i)
    parent.texels[i] = uint8_t(i * 37 + (i >> 7) * 11);
  return parent;
}

inline bool parseCodecFuzzInput(std::span<const uint8_t> data, CodecFuzzInput* input) {
  if (data.size() < kCodecFuzzHeaderBytes) return false;
  const uint32_t codec = (data[0] & 7u) | ((data[1] >> 6) & 1u) << 3;
  input->codec = Codec(codec > uint32_t(Codec::kBc7) ? codec - 8 : codec);
  input->channels = ((data[0] >> 3) & 3) + 1;
  input->round_trip = (data[0] >> 5) & 1;
  input->quadrant_x = (data[0] >> 6) & 1;
  input->quadrant_y = (data[0] >> 7) & 1;
  const uint8_t high_bits = data[0] >> 6;
  input->sample_type =
      input->codec == Codec::kPtm || high_bits == 3 ? SampleType::kU8 : SampleType(high_bits);
  input->width_px = (data[1] & (kCodecFuzzMaxSidePx - 1)) + 1;
  input->height_px = (data[2] & (kCodecFuzzMaxSidePx - 1)) + 1;
  input->rest = data.subspan(kCodecFuzzHeaderBytes);
  return true;
}

/// The header bytes for a decode-mode input (round_trip false) or a round-trip one; ptm's
/// parent quarter is (quadrant, quadrant).
inline std::vector<uint8_t> codecFuzzHeader(Codec codec, uint32_t channels, uint32_t width_px,
                                            uint32_t height_px, bool round_trip,
                                            uint32_t quadrant = 0) {
  return {uint8_t((uint8_t(codec) & 7) | (channels - 1) << 3 | (round_trip ? 1 : 0) << 5 |
                  (quadrant & 1) << 6 | (quadrant & 1) << 7),
          uint8_t((width_px - 1) | (uint8_t(codec) >> 3 & 1) << 6), uint8_t(height_px - 1)};
}

}  // namespace tessera::fuzz
