#pragma once
// Pyramids of small images held in memory (a scene's textures): the same streaming pyramid,
// downsampling, tile cutting and codecs as buildArchive, for one image at a time, returning
// the encoded tiles instead of writing an archive. The scene builder (src/scenebuild) lays the
// tiles out itself.

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <tessera/format.h>
#include <tessera/result.h>

#include "codecs/encode.h"

namespace tessera::detail {

/// One image's tiles: entries[level][y * tilesX(level) + x]; payloads the same shape, empty
/// for tiles that are not kEncoded. Entries' offsets are zero: the caller places payloads.
struct EncodedPyramid {
  ImageInfo info;
  std::vector<std::vector<TileEntry>> entries;
  std::vector<std::vector<std::vector<uint8_t>>> payloads;
};

/// Reads a whole image file (TIFF, PNG or JPEG, chosen by content) through the builder's band
/// readers, in the file's sample type (u8, u16 or f32). Fails naming the path: missing,
/// unreadable, unsupported, truncated, or a side over `max_side_px` (kTooLarge).
[[nodiscard]] Result<Image> readImageFile(const std::string& path, uint32_t max_side_px);

/// The metadata `statistics` of an image (mean, min and max per channel; the counts of NaN and
/// infinities for f32) computed from `level`, one of its levels (builders use the coarsest).
[[nodiscard]] nlohmann::json levelStatistics(const Image& level);

/// `image` with 8-bit samples: u16 rounded from 0..65535 to 0..255, f32 clamped to [0, 1] then
/// scaled (NaN becomes 0). An 8-bit image is returned as is.
[[nodiscard]] Image toEightBit(Image image);

/// Builds and encodes the pyramid of `image` with `info`'s tile size, border, page size and
/// sRGB flag (its size and channels must match the image; level_count is filled in). Tiles
/// that are one colour become uniform entries, all-zero tiles of images with alpha empty ones,
/// as in buildArchive. Codecs coded against a parent tile (ptm) are refused (kUnsupported).
/// `what` prefixes errors. Owned by the calling thread; `scratch` may be null.
[[nodiscard]] Result<EncodedPyramid> encodePyramid(const Image& image, ImageInfo info, Codec codec,
                                                   const EncodeOptions& options,
                                                   CodecScratch* scratch, const std::string& what);

}  // namespace tessera::detail
