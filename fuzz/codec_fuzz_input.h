#pragma once
// The input layout of codec_fuzzer, shared with the seed-corpus generator so both agree:
//   byte 0: bits 0-2 codec (Codec value; 7 reads as kPtm), bits 3-4 channels - 1,
//           bit 5 mode (0: decode the payload, 1: encode the texels, decode, compare)
//   byte 1: width - 1 (low 6 bits), byte 2: height - 1 (low 6 bits): tiles up to 64x64 keep
//           each run fast, and the codecs' size-dependent paths are all reached below that
//   decode mode: bytes 3.. are the payload (ptm: the parent's quarter is the payload length's
//           parity, the same in x and y)
//   round-trip mode: byte 3 JPEG quality (1 + b % 100), byte 4 bits 0-3 effort (0..9),
//           bit 4 chroma subsampling, bits 5 and 6 ptm's parent quarter in x and y; bytes 5..
//           are texels, repeated to fill the tile
// ptm gets a fixed parent for square tiles of even side (codec_fuzzer.cpp, fuzzParent).

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "format/codec.h"

namespace tessera::fuzz {

inline constexpr size_t kCodecFuzzHeaderBytes = 3;
inline constexpr uint32_t kCodecFuzzMaxSidePx = 64;

struct CodecFuzzInput {
  Codec codec;
  uint32_t channels;
  bool round_trip;
  uint32_t width_px;
  uint32_t height_px;
  std::span<const uint8_t> rest;  ///< payload, or options + texels in round-trip mode
};

inline bool parseCodecFuzzInput(std::span<const uint8_t> data, CodecFuzzInput* input) {
  if (data.size() < kCodecFuzzHeaderBytes) return false;
  const uint8_t codec = data[0] & 7;
  input->codec = Codec(std::min<uint8_t>(codec, uint8_t(Codec::kPtm)));
  input->channels = ((data[0] >> 3) & 3) + 1;
  input->round_trip = (data[0] >> 5) & 1;
  input->width_px = (data[1] & (kCodecFuzzMaxSidePx - 1)) + 1;
  input->height_px = (data[2] & (kCodecFuzzMaxSidePx - 1)) + 1;
  input->rest = data.subspan(kCodecFuzzHeaderBytes);
  return true;
}

/// The header bytes for a decode-mode input (round_trip false) or a round-trip one.
inline std::vector<uint8_t> codecFuzzHeader(Codec codec, uint32_t channels, uint32_t width_px,
                                            uint32_t height_px, bool round_trip) {
  return {uint8_t(uint8_t(codec) | (channels - 1) << 3 | (round_trip ? 1 : 0) << 5),
          uint8_t(width_px - 1), uint8_t(height_px - 1)};
}

}  // namespace tessera::fuzz
