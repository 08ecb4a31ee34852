#pragma once
// zdelta: the lossless codec for samples wider than a byte (docs/codecs.md, "zdelta (7)").
// Each sample's bit pattern, as an unsigned integer of its width, is replaced by its difference
// (modulo 2^bits) from the same channel of the texel to its left (the first texel of a row:
// the one above; the first of the tile: zero); the differences are split into byte planes,
// least significant first, and the planes are one zstd frame. Smooth 16-bit and float data
// then has near-constant high planes, which zstd compresses well, and the transform is exactly
// reversible for any bits, NaN payloads and infinities included.

#include <cstdint>
#include <span>
#include <vector>

#include <tessera/codec_scratch.h>
#include <tessera/format.h>
#include <tessera/result.h>

#include "codecs/decode.h"
#include "codecs/encode.h"

namespace tessera::detail {

/// Decode side (tessera::codecs): the contract of DecodeFunction (codecs/decode.h).
Result<void> decodeZdelta(std::span<const uint8_t> payload, Image& out, const ParentTexels* parent,
                          CodecScratch* scratch);
/// Encode side (tessera::encoders): the contract of EncodeFunction (codecs/encode.h).
Result<std::vector<uint8_t>> encodeZdelta(const ImageView& tile, const EncodeOptions& options,
                                          const ParentTexels* parent, CodecScratch* scratch);

}  // namespace tessera::detail
