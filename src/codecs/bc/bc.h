#pragma once
// BC1 and BC7: GPU block-compressed tiles (docs/codecs.md, "bc1 (8) and bc7 (9)"). A payload
// is the stored tile's 4x4 blocks in row-major block order, the tile padded to a multiple of 4
// by repeating its last column and row; the GPU samples it as it is, the CPU decoders here
// serve the reference renderer, verify, export and the server.

#include <cstdint>
#include <span>
#include <vector>

#include "codecs/bc_layout.h"
#include "codecs/encode.h"

namespace tessera::detail {

/// Decodes one BC1 block into 16 RGBA texels, row-major (`rgba` holds 64 bytes).
void decodeBc1Block(const uint8_t* block, uint8_t* rgba);
/// Decodes one BC7 block into 16 RGBA texels. Returns its mode, 6, or -1 (and writes nothing)
/// for a block of another mode or a reserved mode byte, which this decoder does not read.
int decodeBc7Block(const uint8_t* block, uint8_t* rgba);

/// Decode side (tessera::codecs): the contract of DecodeFunction (codecs/decode.h).
Result<void> decodeBc1(std::span<const uint8_t> payload, Image& out, const ParentTexels* parent,
                       CodecScratch* scratch);
Result<void> decodeBc7(std::span<const uint8_t> payload, Image& out, const ParentTexels* parent,
                       CodecScratch* scratch);

/// Encode side (tessera::encoders). BC1 through libsquish (effort 1 range fit, 0 or 2 cluster
/// fit, 3 iterative cluster fit); BC7 through Tessera's own mode-6 encoder (effort 1..4
/// refinement passes, 0 = 1). Tiles with alpha are refused by BC1.
Result<std::vector<uint8_t>> encodeBc1(const ImageView& tile, const EncodeOptions& options,
                                       const ParentTexels* parent, CodecScratch* scratch);
Result<std::vector<uint8_t>> encodeBc7(const ImageView& tile, const EncodeOptions& options,
                                       const ParentTexels* parent, CodecScratch* scratch);

/// The 16 RGBA texels of block (block_x, block_y) of `tile`, texels past the tile's edge
/// repeating its last column and row; grey is spread to RGB, and alpha is 255 without an
/// alpha channel. `tile` holds 8-bit samples.
void gatherBlockRgba(const ImageView& tile, uint32_t block_x, uint32_t block_y, uint8_t* rgba);

}  // namespace tessera::detail
