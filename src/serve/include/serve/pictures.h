#pragma once
// Browser pictures cut from an archive: Deep Zoom and XYZ tiles, and stored tiles transcoded
// to PNG or JPEG. Geometry is specified in docs/serve.md, "Deep Zoom" and "XYZ".

#include <cstdint>
#include <optional>
#include <string>

#include <tessera/archive.h>
#include <tessera/display_window.h>
#include <tessera/result.h>

namespace tessera::detail {

enum class PictureFormat : uint8_t { kPng, kJpeg };

/// "png" or "jpeg"/"jpg" (as `extension` spells it); nullopt for anything else.
std::optional<PictureFormat> parsePictureFormat(std::string_view text);
const char* pictureContentType(PictureFormat format);

/// DZI's finest level index: ceil(log2(max(W, H))); DZI level d shows tessera level
/// dziMaxLevel - d, at any d in [0, dziMaxLevel].
uint32_t dziMaxLevel(const ImageInfo& info);
/// Overlap in the DZI descriptor: the archive's border, so a DZI tile is cut from one stored
/// tile.
inline uint32_t dziOverlap(const ImageInfo& info) {
  return info.border_px;
}
/// The format a DZI descriptor names: jpg for JPEG archives without alpha, png otherwise.
PictureFormat dziFormat(const ImageInfo& info);
/// The file extension of `format` in Deep Zoom paths: "jpg" or "png".
const char* dziExtension(PictureFormat format);
/// Whether a stored payload of `codec` is already a `format` picture of `info`'s tiles (a JPEG
/// only when the image has no alpha), so it can be sent or exported as it is.
bool browserReady(const ImageInfo& info, Codec codec, PictureFormat format);
/// The .dzi descriptor (XML) of `info`: tile size, overlap, format and level-0 size.
std::string dziDescriptor(const ImageInfo& info);
/// The XYZ zoom at which one tile pixel is one level-0 pixel: ceil(log2(max(W, H) / 256)),
/// at least 0.
uint32_t xyzMaxZoom(const ImageInfo& info);
inline constexpr uint32_t kXyzTileSizePx = 256;

/// Width of the image scaled down by 2^scale_log2 (ceil(W / 2^s), at least 1): the size of
/// tessera level s, and of the virtual levels coarser than the archive's coarsest.
uint32_t scaledWidthPx(const ImageInfo& info, uint32_t scale_log2);
uint32_t scaledHeightPx(const ImageInfo& info, uint32_t scale_log2);

/// An encoded picture, or the reason there is none (kNotFound: outside the grid).
struct Picture {
  std::string bytes;
  bool copied = false;  ///< the stored payload as is, neither decoded nor encoded
};

/// Pictures of u16 and f32 images are their samples mapped to RGBA8 by `window`
/// (windowToRgba8; NaN transparent); u8 images ignore it.
///
/// DZI tile (dz_level, col, row) of `image`, edge tiles cropped to the image, encoded in
/// `format`. kNotFound outside the pyramid or the level's tile grid.
[[nodiscard]] Result<Picture> renderDziTile(const Archive& archive, uint32_t image,
                                            uint32_t dz_level, uint32_t col, uint32_t row,
                                            PictureFormat format, int jpeg_quality,
                                            const DisplayWindow& window = {});

/// XYZ tile (z, x, y): always 256 x 256, the part outside the image transparent (PNG) or
/// black (JPEG). kNotFound for z > xyzMaxZoom or a tile wholly outside the image.
[[nodiscard]] Result<Picture> renderXyzTile(const Archive& archive, uint32_t image, uint32_t z,
                                            uint32_t x, uint32_t y, PictureFormat format,
                                            int jpeg_quality, const DisplayWindow& window = {});

/// The stored tile that XYZ tile (z, x, y) of `info` (image number `image`) is exactly: the
/// image has 256-px tiles without border, the zoom maps to a stored level and the tile lies
/// wholly inside the image. nullopt when the XYZ tile is cut, padded or scaled instead.
std::optional<TileId> xyzStoredTile(const ImageInfo& info, uint32_t image, uint32_t z, uint32_t x,
                                    uint32_t y);

/// The colour of a stored tile that has one colour and no payload (uniform, or empty: all
/// zero), as TileEntry::uniform_rgba holds it.
struct UniformTexel {
  uint32_t rgba = 0;  ///< channel c is byte c; channels the image lacks are ignored
};
/// The colour `entry` fills its tile with, for 8-bit images; nullopt for tiles with a payload
/// and for wider samples (whose pictures go through a display window).
std::optional<UniformTexel> uniformTexel(const ImageInfo& info, const TileEntry& entry);
/// The XYZ picture of a stored tile of one colour (xyzStoredTile, uniformTexel): the bytes
/// renderXyzTile returns for it, made without reading the archive, so that a caller writing
/// many such tiles can encode each colour once.
[[nodiscard]] Result<Picture> uniformXyzPicture(const ImageInfo& info, UniformTexel texel,
                                                PictureFormat format, int jpeg_quality);

/// A Deep Zoom tile at a level the archive stores, which is cut from one stored tile (its border
/// is the overlap).
struct DziStoredTile {
  TileId tile;
  uint32_t width_px = 0;  ///< of the Deep Zoom tile: overlap included, cropped to the image
  uint32_t height_px = 0;
};
/// The stored tile Deep Zoom tile (dz_level, col, row) of `info` (image number `image`) is cut
/// from; nullopt outside the grid and at levels coarser than the archive's coarsest.
std::optional<DziStoredTile> dziStoredTile(const ImageInfo& info, uint32_t image, uint32_t dz_level,
                                           uint32_t col, uint32_t row);
/// The Deep Zoom picture cut from a stored tile of one colour (dziStoredTile, uniformTexel):
/// the bytes renderDziTile returns for it, made without reading the archive.
[[nodiscard]] Result<Picture> uniformDziPicture(const ImageInfo& info, UniformTexel texel,
                                                uint32_t width_px, uint32_t height_px,
                                                PictureFormat format, int jpeg_quality);

/// A stored tile (borders included, the stored geometry) decoded and re-encoded: for codecs
/// browsers cannot decode and for empty/uniform tiles, which have no payload. A u16 or f32
/// tile is mapped to RGBA8 by `window` (windowToRgba8: NaN transparent); u8 tiles ignore it.
[[nodiscard]] Result<Picture> transcodeStoredTile(const Archive& archive, const TileId& tile,
                                                  PictureFormat format, int jpeg_quality,
                                                  const DisplayWindow& window = {});

}  // namespace tessera::detail
