#pragma once
// Tile codecs: encode a stored tile (borders included) to a payload and back.
// Pure: spans in, bytes out; no I/O, no threads, no globals. One function pair per codec,
// chosen from a table by `Codec` value (docs/format.md, "Codecs").

#include <cstdint>
#include <span>
#include <vector>

#include <tessera/format.h>
#include <tessera/result.h>

namespace tessera::detail {

/// Encoder settings. `quality` is used by lossy codecs only (JPEG 1..100); `effort` by codecs
/// with a speed/size trade-off (zstd level, PNG/WebP effort), 0 meaning the codec's default.
struct EncodeOptions {
  int quality = 85;
  int effort = 0;
  /// JPEG chroma subsampling: true for 4:2:0 (the default of libvips at Q < 90), false for 4:4:4.
  bool chroma_subsampling = true;
};

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

/// Per-thread reusable state for codecs whose libraries are costly to set up per call
/// (TurboJPEG handles, zstd contexts, scratch buffers). Owned by one thread; a worker keeps one
/// and passes it to every call. Passing null makes the call set up and free its own.
class CodecScratch {
 public:
  CodecScratch();
  ~CodecScratch();
  CodecScratch(const CodecScratch&) = delete;
  CodecScratch& operator=(const CodecScratch&) = delete;
  struct State;  ///< defined in codec_internal.h; members are lazily created per codec
  State& state() { return *state_; }

 private:
  State* state_;
};

/// One codec's implementation. Thread-safe: functions hold no state between calls beyond the
/// caller's `CodecScratch`.
struct CodecFunctions {
  Codec codec;
  /// True when tiles are coded against their decoded parent tile.
  bool needs_parent;
  /// True when `decode(encode(x)) == x` bit for bit.
  bool lossless;
  /// Encodes `tile` (any width/height, `channels` 1..4). Fails only on encoder errors.
  Result<std::vector<uint8_t>> (*encode)(const ImageView& tile, const EncodeOptions& options,
                                         const ParentTexels* parent, CodecScratch* scratch);
  /// Decodes `payload` into `out`, whose width, height and channels are the expected ones
  /// (from the archive, never from the payload). Rejects payloads that disagree with them,
  /// are truncated, have trailing bytes or would write outside `out`. Allocates at most
  /// the size of `out` plus a bounded scratch.
  Result<void> (*decode)(std::span<const uint8_t> payload, Image& out, const ParentTexels* parent,
                         CodecScratch* scratch);
};

/// The table entry for `codec`, or null for codec values this build does not know.
const CodecFunctions* findCodec(Codec codec);

/// Convenience: looks up the codec and encodes; an unimplemented codec is kUnsupported.
Result<std::vector<uint8_t>> encodeTile(Codec codec, const ImageView& tile,
                                        const EncodeOptions& options,
                                        const ParentTexels* parent = nullptr,
                                        CodecScratch* scratch = nullptr);
/// Convenience: looks up the codec and decodes into `out` (see CodecFunctions::decode).
Result<void> decodeTile(Codec codec, std::span<const uint8_t> payload, Image& out,
                        const ParentTexels* parent = nullptr, CodecScratch* scratch = nullptr);

}  // namespace tessera::detail
