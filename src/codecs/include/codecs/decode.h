#pragma once
// The decode side of the codec plug-ins (docs/architecture.md, "Codecs"): what the reader, the
// loader pool and the server need to turn a verified payload into texels. Every codec has a
// folder under src/codecs/ and one row in the decoder table (decoders.cpp); this library never
// contains encoder code, so a viewer that links it links no encoder.

#include <cstdint>
#include <span>

#include <tessera/codec_scratch.h>
#include <tessera/format.h>
#include <tessera/result.h>

namespace tessera::detail {

/// Decoded texels of the parent tile, for codecs that code a tile relative to it
/// (Marvie & Bouatouch's progressive texture maps). Null for other codecs.
///
/// Child stored texel (i, j) lies in the 2x2 block whose parent stored texel is
/// ((quadrant_x * tile_size_px + border_px + i) / 2, (quadrant_y * tile_size_px + border_px + j)
/// / 2): both tiles start `border_px` texels before their tile's origin (docs/format.md, "Tiles").
struct ParentTexels {
  ImageView texels;           ///< the parent's stored tile, borders included
  uint32_t quadrant_x = 0;    ///< which quarter of the parent this tile refines: 0 left, 1 right
  uint32_t quadrant_y = 0;    ///< 0 top, 1 bottom
  uint32_t tile_size_px = 0;  ///< the image's tile size (even), borders excluded
  uint32_t border_px = 0;     ///< the image's border, the same at both levels
};

/// Decodes `payload` into `out`, whose width, height and channels are the expected ones (from
/// the archive, never from the payload). Rejects payloads that disagree with them, are
/// truncated, have trailing bytes or would write outside `out`; allocates at most the size of
/// `out` plus a bounded scratch. `parent` is required by codecs that need one (see
/// codecNeedsParent) below the coarsest level, and ignored by the others.
using DecodeFunction = Result<void> (*)(std::span<const uint8_t> payload, Image& out,
                                        const ParentTexels* parent, CodecScratch* scratch);

/// One codec's decode side. Thread-safe: the function holds no state between calls beyond the
/// caller's CodecScratch.
struct CodecDecoder {
  Codec codec;
  DecodeFunction decode;
};

/// The decoder of `codec`, or null for codec values this build cannot decode.
const CodecDecoder* findDecoder(Codec codec);

/// Looks up the decoder, sizes `out` to its geometry and decodes; an unknown codec is
/// kUnsupported. `out`'s width, height and channels must be set (a contract: checked).
[[nodiscard]] Result<void> decodeTile(Codec codec, std::span<const uint8_t> payload, Image& out,
                                      const ParentTexels* parent = nullptr,
                                      CodecScratch* scratch = nullptr);

/// Whether `payload` is exactly one zstd frame that records `content_bytes` as its content
/// size: the header checks the zstd codec's decoder makes before it decompresses. Such a
/// payload is a zstd tile of that many texel bytes to the archive and to any zstd reader (a
/// TIFF ZSTD tile), which is why the TIFF export and import copy only those. Reads the frame
/// and block headers only; does not decompress or allocate. Safe on any bytes.
bool isWholeZstdFrame(std::span<const uint8_t> payload, size_t content_bytes);

}  // namespace tessera::detail
