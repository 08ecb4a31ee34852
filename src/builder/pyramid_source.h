#pragma once
// Importing pyramids that already exist (docs/import.md): a pyramidal TIFF (SubIFDs or
// reduced-resolution directories, as COG and vips write), a Deep Zoom folder, or a whole-slide
// image through OpenSlide. Stored JPEG tiles that fit the archive are copied as they are;
// every other level is computed, from the nearest finer level the source holds.

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <tessera/format.h>
#include <tessera/result.h>

#include "band_reader.h"

namespace tessera::detail {

/// One level of a source pyramid, finest first.
struct SourceLevel {
  uint32_t width_px = 0;
  uint32_t height_px = 0;
  /// The stored tiles' side when the level is tiled in squares with no overlap, else 0.
  uint32_t tile_size_px = 0;
  /// Tiles are (or become, with their tables spliced in) whole baseline JPEG streams of
  /// tile_size_px square in the source's channel layout (gray, or YCbCr decoding to RGB).
  bool jpeg_tiles = false;
  /// Tiles are zstd-compressed tile_size_px squares of packed little-endian samples, channels
  /// interleaved, with no predictor (a TIFF ZSTD tile): what the zstd codec stores for a
  /// `zstd_sample_type` image of `zstd_channels` channels, once its frame is checked.
  bool zstd_tiles = false;
  SampleType zstd_sample_type = SampleType::kU8;
  uint32_t zstd_channels = 0;
};

/// A stored tile as readTile returns it: a whole JPEG or zstd payload when it can be copied,
/// otherwise the decoded texels of the tile's part of the level (an edge tile that the source
/// crops, a zstd frame the archive's decoder would refuse, padding the archive would not have).
struct SourceTile {
  std::vector<uint8_t> jpeg;  ///< complete JPEG stream (SOI..EOI); empty when texels are set
  /// One zstd frame recording the whole stored tile's byte size (isWholeZstdFrame), padded
  /// as the builder pads an edge tile; empty when jpeg or texels are set.
  std::vector<uint8_t> zstd;
  /// Packed rows in the source's channels and sample type (host byte order).
  std::vector<uint8_t> texels;
  uint32_t width_px = 0;   ///< of texels: the tile's part of the level
  uint32_t height_px = 0;  ///< of texels
};

/// A pyramid already encoded by another tool. Owned by one thread.
class PyramidSource {
 public:
  virtual ~PyramidSource() = default;
  /// Level 0's facts (size, channels, format, metadata), as a band reader of it gives them.
  virtual const SourceInfo& info() const = 0;
  /// Every level the source holds, finest first; levels()[0] is the full image.
  virtual const std::vector<SourceLevel>& levels() const = 0;
  /// Tile (x, y) of a level with jpeg_tiles or zstd_tiles set. Fails naming the file and the tile
  /// when it is missing, truncated or not what the level claims.
  [[nodiscard]] virtual Result<SourceTile> readTile(uint32_t level, uint32_t x, uint32_t y) = 0;
  /// A reader of a level's decoded rows, top to bottom, in info().channels.
  [[nodiscard]] virtual Result<std::unique_ptr<BandReader>> openLevel(uint32_t level) = 0;
};

/// Opens `path` as a pyramid when it is one: a `.dzi` file, a TIFF with reduced-resolution
/// levels (SubIFDs or following directories), a slide OpenSlide recognises by its extension
/// (.svs .ndpi .vms .vmu .scn .mrxs .bif .svslide), or any file named "openslide:PATH".
/// Returns nullptr for a plain image (a single-level TIFF, a PNG, a JPEG, synthetic).
[[nodiscard]] Result<std::unique_ptr<PyramidSource>> openPyramidSource(const std::string& path);

[[nodiscard]] Result<std::unique_ptr<PyramidSource>> openTiffPyramid(const std::string& path);
[[nodiscard]] Result<std::unique_ptr<PyramidSource>> openDeepZoom(const std::string& path);
[[nodiscard]] Result<std::unique_ptr<PyramidSource>> openSlide(const std::string& path);

/// Which archive levels are copied and how the others are computed.
struct ImportPlan {
  /// Per archive level: the source level copied tile for tile, or -1.
  std::vector<int> copied_from;
  /// A pass streams the decoded rows of `source_level` (whose size is archive level
  /// `first_level`'s) through the pyramid and keeps levels first_level..last_level that are
  /// not copied.
  struct Pass {
    uint32_t source_level = 0;
    uint32_t first_level = 0;
    uint32_t last_level = 0;
  };
  std::vector<Pass> passes;
};

/// Plans an import into archive geometry `info` (level_count set): a source level matches an
/// archive level when its size is the archive's ceil(w / 2^L) x ceil(h / 2^L); a match is
/// copied when its tiles are of the archive's tile size, the archive has no border, and either
/// they are JPEG and the archive is JPEG, or they are zstd of the archive's sample type (u16 or
/// f32) and channels and the archive is zstd (8-bit zstd tiles are computed: the build marks
/// uniform 8-bit tiles, which a copy would not). The coarsest level is always computed (its
/// statistics go into the metadata); every computed level comes from the nearest finer matching
/// level. Without `reuse_levels` (codecs that code a tile against its parent) the plan is one pass
/// from level 0, as a plain build.
ImportPlan planImport(const ImageInfo& info, const std::vector<SourceLevel>& levels,
                      bool reuse_levels);

/// Makes a whole JPEG stream out of a TIFF's abbreviated tile: the JPEGTables' DQT/DHT
/// segments are spliced in after the tile's SOI. `tables` may be empty (the tile is whole).
/// Fails when either is not a JPEG stream.
[[nodiscard]] Result<std::vector<uint8_t>> completeTiffJpeg(std::span<const uint8_t> tables,
                                                            std::span<const uint8_t> tile);

/// Checks that a JPEG to be copied is `side_px` square with `channels` components (1 or 3)
/// and Huffman-coded, so the archive's decoder takes it; fails naming `what`.
[[nodiscard]] Result<void> checkJpegTile(std::span<const uint8_t> jpeg, uint32_t side_px,
                                         uint32_t channels, const std::string& what);

}  // namespace tessera::detail
