#pragma once
/// \file
/// The archive format's vocabulary: tile addresses, tile kinds, codecs, per-image geometry and
/// the image buffers that tiles decode into. The byte layout is specified in docs/format.md;
/// `src/format` mirrors its sections. Everything here is plain data: thread-compatible.

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace tessera {

/// Format version written by this build. Readers accept any minor of the same major
/// (docs/format.md, "Versioning").
inline constexpr uint16_t kFormatVersionMajor = 1;
inline constexpr uint16_t kFormatVersionMinor = 0;

/// Bounds from docs/format.md, "Images".
inline constexpr uint32_t kMinTileSizePx = 64;
inline constexpr uint32_t kMaxTileSizePx = 2048;
inline constexpr uint32_t kMaxBorderPx = 16;
/// Largest image side in pixels. 2^24 keeps every level's tile count and every texel index
/// of a 2048-px tile well inside 64-bit arithmetic, and is 64x the 262144 px we test.
inline constexpr uint32_t kMaxImageSidePx = 1u << 24;
inline constexpr uint32_t kMaxImages = 65536;

/// How a tile's texels are stored (docs/format.md, "Tile entries").
enum class TileKind : uint8_t {
  kEmpty = 0,    ///< no data: decodes to all-zero texels (transparent where there is alpha)
  kUniform = 1,  ///< every texel, border and padding included, has the colour in the entry
  kEncoded = 2,  ///< a payload in the file, decoded by the entry's codec
  kProcedural =
      3,  ///< format 1.1: composited at load time from an instance page (docs/procedural.md)
};

/// Payload codecs. Values are stable on disk; new codecs take new numbers.
enum class Codec : uint8_t {
  kRaw = 0,   ///< texels row-major, interleaved channels, no compression
  kZstd = 1,  ///< raw texels compressed with zstd
  kLz4 = 2,   ///< raw texels compressed with LZ4 (block format, size known from geometry)
  kJpeg = 3,  ///< baseline JPEG (lossy); alpha, when present, as a zstd plane after it
  kPng = 4,   ///< PNG, lossless
  kWebp = 5,  ///< WebP lossless
  kPtm = 6,   ///< progressive texture map coded against the parent tile (Marvie & Bouatouch)
  /// Samples delta-coded along rows and split into byte planes, then zstd: the lossless codec
  /// for 16-bit and float images (docs/codecs.md, "zdelta (7)").
  kZdelta = 7,
  /// BC1 (DXT1) 4x4 blocks of the stored tile, padded to a multiple of 4, uploaded to the GPU
  /// as they are (docs/codecs.md, "bc1 (8) and bc7 (9)"); lossy, no alpha.
  kBc1 = 8,
  /// BC7 4x4 blocks, as kBc1 but 16 bytes a block, with alpha (docs/codecs.md).
  kBc7 = 9,
};

/// What one sample (one channel of one texel) is. Values are stable on disk (image record
/// byte 15, docs/format.md, "Sample types"); samples are stored little-endian.
enum class SampleType : uint8_t {
  kU8 = 0,   ///< 8-bit unsigned
  kU16 = 1,  ///< 16-bit unsigned
  kF32 = 2,  ///< 32-bit IEEE 754 float; NaN and infinities are stored as they are
};

/// Format minor version an archive needs when an image's samples are not 8-bit. Archives
/// whose images are all 8-bit keep the minor they had (0, or 1 with a section table).
inline constexpr uint16_t kSampleTypeMinorVersion = 2;

/// Bytes of one sample: 1, 2 or 4.
constexpr uint32_t sampleBytes(SampleType type) {
  return type == SampleType::kF32 ? 4 : type == SampleType::kU16 ? 2 : 1;
}
/// Names a sample type for the CLI and JSON: "u8", "u16", "f32".
const char* sampleTypeName(SampleType type);
/// Parses a sample type name; returns false for an unknown name.
bool parseSampleTypeName(std::string_view name, SampleType* type);
/// True when `codec` can store samples of `type`: raw, zstd, lz4 and zdelta store any type,
/// png 8- and 16-bit, jpeg, webp, ptm, bc1 and bc7 only 8-bit.
bool codecSupportsSampleType(Codec codec, SampleType type);

/// Names a codec for the CLI and JSON: "raw", "zstd", "lz4", "jpeg", "png", "webp", "ptm",
/// "zdelta", "bc1", "bc7".
const char* codecName(Codec codec);
/// Parses a codec name; returns false for an unknown name.
bool parseCodecName(std::string_view name, Codec* codec);
/// True for a codec whose tiles below the coarsest level decode only against their decoded
/// parent tile (ptm): a loader must decode the parent first (docs/runtime.md, "Dependent
/// codecs").
bool codecNeedsParent(Codec codec);
/// True for a codec whose decoded texels equal the encoded ones bit for bit (every codec but
/// JPEG); false for an unknown value.
bool codecIsLossless(Codec codec);
/// Names a tile kind: "empty", "uniform", "encoded", "procedural".
const char* tileKindName(TileKind kind);

/// Payload order in the file (docs/format.md, "Clustering").
enum class TileOrder : uint8_t {
  kHilbert = 0,   ///< coarse levels first, Hilbert curve within each level
  kQuadtree = 1,  ///< depth-first quadtree, parent before children (Zhou et al.)
  kRowMajor = 2,  ///< coarse levels first, row by row within each level
};

/// A tile's address: image index, pyramid level (0 = full resolution), column and row.
struct TileId {
  uint32_t image = 0;
  uint32_t level = 0;
  uint32_t x = 0;
  uint32_t y = 0;
  friend bool operator==(const TileId&, const TileId&) = default;
};

/// A tile's directory entry (docs/format.md, "Tile entries").
struct TileEntry {
  TileKind kind = TileKind::kEmpty;
  Codec codec = Codec::kRaw;
  uint64_t offset_bytes = 0;  ///< payload offset in the file; 0 unless hasPayload()
  uint32_t length_bytes = 0;  ///< payload length; 0 unless hasPayload()
  uint64_t checksum = 0;      ///< xxh3-64 of the payload; 0 unless hasPayload()
  uint32_t uniform_rgba = 0;  ///< kUniform: channel c of the colour is byte c (little-endian)
  /// Whether the tile has bytes in the file to read (and verify) before it can be decoded: an
  /// encoded payload, or a procedural tile's instance page. Loaders fetch exactly these.
  bool hasPayload() const { return kind == TileKind::kEncoded || kind == TileKind::kProcedural; }
};

/// Geometry of one image of an archive. Level dimensions follow from it:
/// `levelWidthPx(L) = max(1, ceil(width_px / 2^L))`, and each level is padded to whole tiles
/// (Backes et al., eq. 1). The coarsest level is the first that fits in one tile.
struct ImageInfo {
  uint32_t width_px = 0;         ///< level 0 width, 1..kMaxImageSidePx
  uint32_t height_px = 0;        ///< level 0 height, 1..kMaxImageSidePx
  uint32_t channels = 0;         ///< 1 gray, 2 gray+alpha, 3 RGB, 4 RGBA
  uint32_t tile_size_px = 0;     ///< power of two, kMinTileSizePx..kMaxTileSizePx
  uint32_t border_px = 0;        ///< texels copied from neighbours on each side, 0..kMaxBorderPx
  uint32_t level_count = 0;      ///< levels stored, derived from size and tile size
  uint32_t page_tiles_log2 = 5;  ///< a directory page covers 2^n x 2^n tiles
  Codec default_codec = Codec::kZstd;
  bool srgb_downsample = false;  ///< levels averaged in linear light rather than sRGB codes
  std::string name;              ///< from metadata; "" when unnamed
  SampleType sample_type = SampleType::kU8;  ///< what each channel of a texel is

  uint32_t levelWidthPx(uint32_t level) const;
  uint32_t levelHeightPx(uint32_t level) const;
  uint32_t tilesX(uint32_t level) const;
  uint32_t tilesY(uint32_t level) const;
  /// Side of a stored tile including borders: tile_size_px + 2 * border_px.
  uint32_t storedTileSidePx() const { return tile_size_px + 2 * border_px; }
  /// Bytes of one texel: channels times the sample size.
  uint32_t texelBytes() const { return channels * sampleBytes(sample_type); }
  /// Bytes of one decoded tile including borders.
  size_t storedTileBytes() const {
    return size_t(storedTileSidePx()) * storedTileSidePx() * texelBytes();
  }
};

/// Number of levels for a size: levels until both sides fit in one tile (at least 1).
uint32_t levelCountFor(uint32_t width_px, uint32_t height_px, uint32_t tile_size_px);

/// A read-only view of texels, rows `stride_bytes` apart. Does not own its memory. Samples
/// are `sample_type` in host (little-endian) order.
struct ImageView {
  const uint8_t* data = nullptr;
  uint32_t width_px = 0;
  uint32_t height_px = 0;
  uint32_t channels = 0;
  size_t stride_bytes = 0;
  SampleType sample_type = SampleType::kU8;
  const uint8_t* row(uint32_t y) const { return data + y * stride_bytes; }
  uint32_t texelBytes() const { return channels * sampleBytes(sample_type); }
};

/// An owned image with tightly packed rows.
struct Image {
  uint32_t width_px = 0;
  uint32_t height_px = 0;
  uint32_t channels = 0;
  std::vector<uint8_t> texels;  ///< width_px * height_px * texelBytes() bytes
  SampleType sample_type = SampleType::kU8;

  Image() = default;
  Image(uint32_t width, uint32_t height, uint32_t channel_count, SampleType type = SampleType::kU8)
      : width_px(width),
        height_px(height),
        channels(channel_count),
        texels(size_t(width) * height * channel_count * sampleBytes(type)),
        sample_type(type) {}
  uint32_t texelBytes() const { return channels * sampleBytes(sample_type); }
  size_t strideBytes() const { return size_t(width_px) * texelBytes(); }
  uint8_t* row(uint32_t y) { return texels.data() + y * strideBytes(); }
  const uint8_t* row(uint32_t y) const { return texels.data() + y * strideBytes(); }
  ImageView view() const {
    return {texels.data(), width_px, height_px, channels, strideBytes(), sample_type};
  }
};

}  // namespace tessera
