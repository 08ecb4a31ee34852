#pragma once
/// \file
/// Procedural tiles (Demeulemeester et al., "Combining texture streaming and run-time
/// generation"): a tile composited at load time from brush instances instead of stored texels.
/// This header holds the vocabulary (brushes, instances, blend modes) shared by the brush
/// database (tessera/brushes.h), the compositor and the builder's analysis phase, and the
/// compositor's entry points. The rules are in docs/procedural.md; the bytes in docs/format.md,
/// "Procedural tiles". Plain data and free functions: thread-compatible.

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <tessera/format.h>
#include <tessera/result.h>

namespace tessera {
class Archive;
}

namespace tessera {

/// How a brush texel combines with what lies below it (the W3C compositing formulas,
/// docs/procedural.md, "Blend modes"). Values are stable on disk.
enum class BlendMode : uint8_t {
  kNormal = 0,    ///< B(b, s) = s
  kMultiply = 1,  ///< B(b, s) = b * s
  kAdd = 2,       ///< B(b, s) = min(1, b + s) (linear dodge)
  kOverlay = 3,   ///< B(b, s) = b < 1/2 ? 2 b s : 1 - 2 (1 - b)(1 - s)
};
inline constexpr uint8_t kBlendModeCount = 4;

/// The underlying layer a brush reads to mask itself (seed 001: "rock where steep"). Values
/// are stable on disk.
enum class MaskSource : uint8_t {
  kNone = 0,    ///< no mask: the brush is drawn wherever its image has alpha
  kHeight = 1,  ///< the height layer (a DEM), 0..255
  kSlope = 2,   ///< the slope layer derived from the DEM, 0..255 (docs/procedural.md)
};

/// Names for the CLI, JSON and the database: "normal", "multiply", "add", "overlay";
/// "none", "height", "slope". The parsers return false for unknown names.
const char* blendModeName(BlendMode mode);
bool parseBlendModeName(std::string_view name, BlendMode* mode);
const char* maskSourceName(MaskSource source);
bool parseMaskSourceName(std::string_view name, MaskSource* source);

/// Largest side of a brush image, in texels. Keeps every brush texel coordinate of the
/// compositor's 16.16 fixed point well inside 32 bits.
inline constexpr uint32_t kMaxBrushSidePx = 4096;
/// Images (variants) per brush.
inline constexpr uint32_t kMaxBrushImages = 16;

/// A painting primitive: source images (RGBA, straight alpha), a blend mode and an optional
/// mask from the underlying layer. An instance picks one image by its `variant`.
struct Brush {
  std::string name;  ///< unique in a database; not stored in archives (metadata only)
  BlendMode blend = BlendMode::kNormal;
  MaskSource mask = MaskSource::kNone;
  /// The mask ramps linearly from 0 at `mask_low` to full at `mask_high` (layer units 0..255);
  /// mask_low > mask_high inverts it ("grass where flat"); equal values make a hard step.
  uint8_t mask_low = 0;
  uint8_t mask_high = 255;
  std::vector<Image> images;  ///< 1..kMaxBrushImages, each 4 channels, sides 1..kMaxBrushSidePx
};

/// One stamp of a brush in texture space (seed 001: "a brush ID, a coordinate and radius in
/// texture space, and a set of parameters"). Coordinates in level-0 texels, (0, 0) the image's
/// top-left corner.
struct BrushInstance {
  uint64_t id = 0;                   ///< the database's id; breaks ties in layer order
  uint32_t brush = 0;                ///< index of the brush in the brush set (database: its id)
  double x_px = 0;                   ///< centre
  double y_px = 0;                   ///< centre
  float radius_px = 1;               ///< half of the image's longer side at scale 1, > 0
  float rotation_rad = 0;            ///< counter-clockwise on screen (y down), finite
  float scale = 1;                   ///< multiplies the radius, > 0
  uint8_t opacity = 255;             ///< multiplies the image's alpha
  uint8_t variant = 0;               ///< which of the brush's images (modulo their count)
  uint32_t tint_rgba = 0xFFFFFFFFu;  ///< multiplies colour and alpha; byte c is channel c
  int32_t layer = 0;                 ///< drawing order: lower first; ties by id
};

/// The axis-aligned box that contains everything an instance can draw at any level, in
/// level-0 texels: centre +- radius * scale * sqrt(2) (the circle around the image's rectangle
/// whatever its rotation or aspect). The spatial database indexes this box.
struct BoxPx {
  double x0 = 0, y0 = 0, x1 = 0, y1 = 0;  ///< [x0, x1] x [y0, y1]
  bool intersects(const BoxPx& o) const {
    return x0 <= o.x1 && o.x0 <= x1 && y0 <= o.y1 && o.y0 <= y1;
  }
};
BoxPx instanceBounds(const BrushInstance& instance);

/// Drawing order: layer, then id.
inline bool drawsBefore(const BrushInstance& a, const BrushInstance& b) {
  return a.layer != b.layer ? a.layer < b.layer : a.id < b.id;
}

/// Checks an instance's fields (finite position, radius and scale > 0, finite rotation);
/// the message names `what`.
[[nodiscard]] Result<void> validateInstance(const BrushInstance& instance, const std::string& what);
/// Checks a brush (images present, RGBA, within kMaxBrushSidePx).
[[nodiscard]] Result<void> validateBrush(const Brush& brush, const std::string& what);

/// The underlying layer procedural brushes read: a height image (a DEM, 8-bit gray) covering
/// the whole texture, any resolution. The slope layer is derived from it (docs/procedural.md).
struct UnderlyingLayer {
  Image height;  ///< 1 channel; empty (0x0) when there is none
};

/// Brushes with their mip pyramids and the underlying layer's pyramids, ready to composite.
/// Immutable after `prepare`; thread-safe to share between compositing threads.
class BrushSet {
 public:
  /// Builds each brush image's mip pyramid (alpha-weighted 2x2 means, colour bled into
  /// transparent texels) and the height and slope pyramids. Fails naming the brush.
  [[nodiscard]] static Result<std::shared_ptr<const BrushSet>> prepare(std::vector<Brush> brushes,
                                                                       UnderlyingLayer layer,
                                                                       uint32_t texture_width_px,
                                                                       uint32_t texture_height_px);
  ~BrushSet();
  BrushSet(const BrushSet&) = delete;
  BrushSet& operator=(const BrushSet&) = delete;

  const std::vector<Brush>& brushes() const;
  uint32_t textureWidthPx() const;
  uint32_t textureHeightPx() const;
  bool hasLayer() const;

  struct Impl;
  const Impl& impl() const { return *impl_; }

 private:
  explicit BrushSet(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// Where a composited tile lies: the stored tile (borders included) of `level`, as in
/// docs/format.md, "Tiles": texel (i, j) is the level texel (x*t - border + i, y*t - border + j)
/// clamped to the level's image.
struct TileGeometry {
  uint32_t level = 0;
  uint32_t x = 0;
  uint32_t y = 0;
  uint32_t tile_size_px = 256;
  uint32_t border_px = 0;
  uint32_t image_width_px = 0;   ///< level 0
  uint32_t image_height_px = 0;  ///< level 0
  uint32_t sidePx() const { return tile_size_px + 2 * border_px; }
};

/// The tile's query box: the level-0 area whose instances can touch the tile. The stored
/// tile's texels grown by three texels of the level: an instance draws up to its `reach`
/// (docs/procedural.md, "Compositing"), which passes instanceBounds by up to three texels of
/// the level where the fringe of a magnified brush image leaves the bounds' corner.
BoxPx tileQueryBox(const TileGeometry& tile);

/// The stored-tile texels one instance of a tile's page may change: [x0, x1) x [y0, y1), in
/// stored-tile texel indices (borders included). The analysis phase clips an instance to the
/// texels where it is not replaced by an opaque normal-mode texel of a later instance; outside
/// the clip it would only draw what is then replaced exactly, so clipping never changes a pixel.
struct TileClip {
  uint16_t x0 = 0, y0 = 0, x1 = 0xFFFF, y1 = 0xFFFF;  ///< the default clips nothing
  friend bool operator==(const TileClip&, const TileClip&) = default;
};

/// Composites `instances` (in drawing order: the caller sorts with drawsBefore) into a stored
/// tile: sidePx() square, 4 channels, straight alpha, starting from transparent black.
/// Deterministic to the bit on every machine (integer arithmetic after a per-instance setup in
/// IEEE double without library calls). Instances that do not touch the tile draw nothing.
/// Fails (kCorrupt) when an instance names a brush the set lacks: a tile is never drawn with
/// a brush missing. `out` is resized; its buffer is reused. `clips`, when not empty, holds one
/// TileClip per instance.
[[nodiscard]] Result<void> compositeTile(const BrushSet& brushes, const TileGeometry& tile,
                                         std::span<const BrushInstance> instances, Image& out,
                                         std::span<const TileClip> clips = {});

/// The same, by brute force: every instance at every texel of the tile, no bounding boxes,
/// no spans. The test oracle for compositeTile and culling.
[[nodiscard]] Result<void> compositeTileReference(const BrushSet& brushes, const TileGeometry& tile,
                                                  std::span<const BrushInstance> instances,
                                                  Image& out);

/// Composites procedural tiles in place of compositeTile, with the same contract (the same
/// stored tile from the same inputs; kCorrupt for a missing brush): what Archive uses when one
/// is set (Archive::setTileCompositor), for example the GPU compositor (tessera/gl.h,
/// createGpuTileCompositor). Called from any thread that decodes tiles, concurrently:
/// implementations are thread-safe.
class TileCompositor {
 public:
  virtual ~TileCompositor() = default;
  [[nodiscard]] virtual Result<void> composite(const std::shared_ptr<const BrushSet>& brushes,
                                               const TileGeometry& tile,
                                               std::span<const BrushInstance> instances,
                                               std::span<const TileClip> clips, Image& out) = 0;
};

/// The procedural side of an archive of format 1.1 (docs/format.md, "Procedural tiles"): its
/// brush set, loaded once, and the compositing of procedural tiles from their instance pages.
/// Immutable after `open`: thread-safe, any thread may composite. Archive::procedural() holds
/// one per archive and Archive::decodeTile composites through it, so most callers never name
/// this class.
class ProceduralTiles {
 public:
  /// Reads the section table's procedural directory, every brush image and the height layer
  /// (each checksummed and decoded), and prepares the brush set. kNotFound when the archive has no
  /// procedural tiles (format 1.0, or a 1.1 file without the directory); errors name the
  /// archive and the block.
  [[nodiscard]] static Result<std::shared_ptr<const ProceduralTiles>> open(const Archive& archive);
  ~ProceduralTiles();
  ProceduralTiles(const ProceduralTiles&) = delete;
  ProceduralTiles& operator=(const ProceduralTiles&) = delete;

  /// The archive image whose tiles may be procedural.
  uint32_t image() const;
  const BrushSet& brushSet() const;
  /// Bytes of the brush images and layer as stored (the "stored once" cost).
  uint64_t storedBrushBytes() const;

  /// Reads a procedural tile's instance page, verifies its checksum, decodes it and composites
  /// the stored tile (4 channels). A page that fails its checksum or structure, or an instance
  /// naming a brush the archive lacks, fails this tile (kCorrupt, naming it): never a picture.
  [[nodiscard]] Result<void> compositeTile(const Archive& archive, const TileId& tile,
                                           const TileEntry& entry, Image& out) const;
  /// The same from page bytes the caller read (and has not verified): checks length and
  /// checksum against `entry` first. `out` is resized to the stored tile (4 channels).
  [[nodiscard]] Result<void> compositePage(const Archive& archive, const TileId& tile,
                                           const TileEntry& entry, std::span<const uint8_t> page,
                                           Image& out) const;
  /// Checks a page without compositing it (verify's fast mode): length and checksum against
  /// `entry`, the page's structure, and that every instance names a brush the archive stores.
  [[nodiscard]] Result<void> checkPage(const Archive& archive, const TileId& tile,
                                       const TileEntry& entry, std::span<const uint8_t> page) const;

  struct Impl;

 private:
  explicit ProceduralTiles(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace tessera
