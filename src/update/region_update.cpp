// updateRegion: a patch of level 0 and the tiles it changes at every level, recomputed from the
// stored neighbours (docs/update.md, "Region update").
#include <algorithm>
#include <cstring>

#include <fmt/format.h>

#include <tessera/archive.h>

#include "archive_tail.h"
#include "builder/downsample.h"
#include "builder/texture_pyramid.h"
#include "codecs/encode.h"
#include "format/metadata.h"
#include "level_pages.h"
#include "update/archive_update.h"

namespace tessera::detail {

namespace {

/// [x0, x1) x [y0, y1) in texels of one level.
struct TexelRect {
  uint32_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
};

/// Texels of one level over `rect`, rows packed.
struct LevelWindow {
  TexelRect rect;
  Image texels;
  uint8_t* at(uint32_t x, uint32_t y) {
    return texels.row(y - rect.y0) + size_t(x - rect.x0) * texels.channels;
  }
};

/// The tiles whose stored texels (borders included) touch `changed`, as a tile rect.
TexelRect affectedTiles(const ImageInfo& info, uint32_t level, const TexelRect& changed) {
  const uint32_t t = info.tile_size_px, b = info.border_px;
  return {changed.x0 >= b ? (changed.x0 - b) / t : 0, changed.y0 >= b ? (changed.y0 - b) / t : 0,
          std::min(info.tilesX(level), (changed.x1 - 1 + b) / t + 1),
          std::min(info.tilesY(level), (changed.y1 - 1 + b) / t + 1)};
}

/// The level texels the stored tiles of `tiles` hold, from the committed version: every texel
/// their recut needs, since a stored tile samples only its own extent, clamped to the level.
Result<LevelWindow> decodeWindow(const Archive& archive, uint32_t image, uint32_t level,
                                 const TexelRect& tiles) {
  const ImageInfo& info = archive.images()[image];
  const int64_t t = info.tile_size_px, b = info.border_px;
  const int64_t w = info.levelWidthPx(level), h = info.levelHeightPx(level);
  LevelWindow window;
  window.rect = {uint32_t(std::max<int64_t>(0, tiles.x0 * t - b)),
                 uint32_t(std::max<int64_t>(0, tiles.y0 * t - b)),
                 uint32_t(std::min<int64_t>(w, tiles.x1 * t + b)),
                 uint32_t(std::min<int64_t>(h, tiles.y1 * t + b))};
  window.texels =
      Image(window.rect.x1 - window.rect.x0, window.rect.y1 - window.rect.y0, info.channels);
  CodecScratch scratch;
  const uint32_t side = info.storedTileSidePx();
  for (uint32_t ty = tiles.y0; ty < tiles.y1; ++ty) {
    for (uint32_t tx = tiles.x0; tx < tiles.x1; ++tx) {
      TESSERA_ASSIGN_OR_RETURN(Image tile, archive.readTile({image, level, tx, ty}, &scratch));
      for (uint32_t j = 0; j < side; ++j) {
        const int64_t y = int64_t(ty) * t - b + j;
        if (y < window.rect.y0 || y >= window.rect.y1) continue;
        const int64_t x_first = std::max<int64_t>(int64_t(tx) * t - b, window.rect.x0);
        const int64_t x_end = std::min<int64_t>(int64_t(tx) * t - b + side, window.rect.x1);
        if (x_first >= x_end) continue;
        const uint32_t i = uint32_t(x_first - (int64_t(tx) * t - b));
        std::memcpy(window.at(uint32_t(x_first), uint32_t(y)),
                    tile.row(j) + size_t(i) * info.channels,
                    size_t(x_end - x_first) * info.channels);
      }
    }
  }
  return window;
}

/// Tile (tx, ty) cut from the window as the builder cuts it from the level: texels outside the
/// level replicate the nearest edge texel.
void cutFromWindow(LevelWindow& window, const ImageInfo& info, uint32_t level, uint32_t tx,
                   uint32_t ty, std::vector<uint8_t>& out) {
  const int64_t t = info.tile_size_px, b = info.border_px;
  const int64_t w = info.levelWidthPx(level), h = info.levelHeightPx(level);
  const uint32_t side = info.storedTileSidePx(), channels = info.channels;
  out.resize(info.storedTileBytes());
  for (uint32_t j = 0; j < side; ++j) {
    const int64_t y = std::clamp<int64_t>(int64_t(ty) * t - b + j, 0, h - 1);
    for (uint32_t i = 0; i < side; ++i) {
      const int64_t x = std::clamp<int64_t>(int64_t(tx) * t - b + i, 0, w - 1);
      std::memcpy(out.data() + (size_t(j) * side + i) * channels,
                  window.at(uint32_t(x), uint32_t(y)), channels);
    }
  }
}

/// The entry a tile's texels get, as buildArchive classifies them: empty (all zero with
/// alpha), uniform (one colour), else encoded and appended.
Result<TileEntry> storeTile(ArchiveTail& tail, const ImageInfo& info, const EncodeOptions& options,
                            const std::vector<uint8_t>& texels, CodecScratch& scratch,
                            const std::string& what) {
  const uint32_t channels = info.channels;
  bool uniform = true;
  for (size_t i = channels; i < texels.size() && uniform; i += channels)
    uniform = std::memcmp(texels.data() + i, texels.data(), channels) == 0;
  TileEntry entry;
  if (uniform) {
    uint32_t colour = 0;
    for (uint32_t c = 0; c < channels; ++c) colour |= uint32_t(texels[c]) << (8 * c);
    const bool has_alpha = channels == 2 || channels == 4;
    entry.kind = has_alpha && colour == 0 ? TileKind::kEmpty : TileKind::kUniform;
    if (entry.kind == TileKind::kUniform) entry.uniform_rgba = colour;
    return entry;
  }
  const uint32_t side = info.storedTileSidePx();
  ImageView view{texels.data(), side, side, channels, size_t(side) * channels};
  auto payload = encodeTile(info.default_codec, view, options, nullptr, &scratch);
  if (!payload) return fail(payload.error().code, what + ": " + payload.error().message);
  TESSERA_ASSIGN_OR_RETURN(BlockRef block, tail.append(*payload));
  entry.kind = TileKind::kEncoded;
  entry.codec = info.default_codec;
  entry.offset_bytes = block.offset_bytes;
  entry.length_bytes = uint32_t(block.length_bytes);
  entry.checksum = block.checksum;
  return entry;
}

/// The next level's changed rect and its new texels, averaged from `window` as the builder's
/// pyramid averages (docs/format.md, "Levels").
LevelWindow downsampleChanged(LevelWindow& window, const ImageInfo& info, uint32_t level,
                              const TexelRect& changed) {
  const uint32_t w = info.levelWidthPx(level), h = info.levelHeightPx(level);
  LevelWindow next;
  next.rect = {changed.x0 / 2, changed.y0 / 2, (changed.x1 + 1) / 2, (changed.y1 + 1) / 2};
  next.texels = Image(next.rect.x1 - next.rect.x0, next.rect.y1 - next.rect.y0, info.channels);
  const uint32_t source_x = 2 * next.rect.x0;
  const uint32_t source_width = std::min(2 * next.rect.x1, w) - source_x;
  for (uint32_t y = next.rect.y0; y < next.rect.y1; ++y) {
    const uint32_t top = 2 * y, bottom = std::min(2 * y + 1, h - 1);
    downsampleRowPair(window.at(source_x, top), window.at(source_x, bottom), source_width,
                      info.channels, info.srgb_downsample, next.at(next.rect.x0, y));
  }
  return next;
}

// Re-encoded tiles take the build's settings: one of the wrong type is refused by name, not
// replaced by a default that would code them unlike their neighbours.
Result<EncodeOptions> buildEncodeOptions(const nlohmann::json& metadata, const std::string& path) {
  EncodeOptions options;
  const auto build = metadata.find("build");
  if (build == metadata.end() || !build->is_object()) return options;
  if (const auto quality = build->find("quality"); quality != build->end()) {
    TESSERA_ASSIGN_OR_RETURN(options.quality, metadataInt(*quality, path, "build.quality"));
  }
  if (const auto effort = build->find("effort"); effort != build->end()) {
    TESSERA_ASSIGN_OR_RETURN(options.effort, metadataInt(*effort, path, "build.effort"));
  }
  const auto chroma = build->find("chroma_subsampling");
  options.chroma_subsampling = chroma == build->end() || *chroma == "4:2:0";
  return options;
}

Result<void> checkPatch(ArchiveTail& tail, uint32_t image, uint32_t x, uint32_t y,
                        const Image& patch, const std::string& patch_name) {
  const std::string& path = tail.path();
  if (image >= tail.header().image_count)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: no image {} (the archive holds {}, numbered from 0)", path, image,
                            tail.header().image_count));
  const ImageInfo& info = tail.records()[image].info;
  if (patch.width_px == 0 || patch.height_px == 0)
    return fail(ErrorCode::kInvalidArgument, patch_name + ": an empty patch changes nothing");
  if (patch.channels != info.channels)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: {} channels, image {} of {} has {}", patch_name, patch.channels,
                            image, path, info.channels));
  if (uint64_t(x) + patch.width_px > info.width_px ||
      uint64_t(y) + patch.height_px > info.height_px)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: a {}x{} patch at {},{} reaches outside image {} of {} ({}x{})",
                            patch_name, patch.width_px, patch.height_px, x, y, image, path,
                            info.width_px, info.height_px));
  // The updater averages and cuts 8-bit texels only (builder/downsample.h's byte rules).
  if (info.sample_type != SampleType::kU8 || patch.sample_type != SampleType::kU8)
    return fail(ErrorCode::kUnsupported,
                fmt::format("{}: image {} has {} samples and {} {}; update supports 8-bit images "
                            "and patches (rebuild wider ones)",
                            path, image, sampleTypeName(info.sample_type), patch_name,
                            sampleTypeName(patch.sample_type)));
  if (codecNeedsParent(info.default_codec))
    return fail(ErrorCode::kUnsupported,
                fmt::format("{}: image {} is coded with {}, whose tiles depend on their parents; "
                            "update supports the other codecs",
                            path, image, codecName(info.default_codec)));
  return {};
}

// The coarsest level is one tile, so its window is the whole level with the patch pasted:
// the statistics a build of the patched image records.
void refreshStatistics(nlohmann::json& metadata, uint32_t image, const LevelWindow& coarsest) {
  nlohmann::json* images = metadata.contains("images") ? &metadata["images"] : nullptr;
  if (!images || !images->is_array() || image >= images->size()) return;
  nlohmann::json& entry = (*images)[image];
  if (!entry.is_object() || !entry.contains("statistics")) return;
  entry["statistics"] = levelStatistics(coarsest.texels);
}

}  // namespace

Result<UpdateReport> updateRegion(const std::string& path, uint32_t image, uint32_t x, uint32_t y,
                                  const Image& patch, const std::string& patch_name) {
  TESSERA_ASSIGN_OR_RETURN(ArchiveTail tail, ArchiveTail::open(path));
  TESSERA_TRY(checkPatch(tail, image, x, y, patch, patch_name));
  TESSERA_ASSIGN_OR_RETURN(std::shared_ptr<Archive> archive, Archive::openFile(path));
  const ImageInfo& info = archive->images()[image];
  TESSERA_ASSIGN_OR_RETURN(const EncodeOptions options,
                           buildEncodeOptions(tail.metadata(), tail.path()));
  LevelWindow changed{{x, y, x + patch.width_px, y + patch.height_px}, patch};
  CodecScratch scratch;
  std::vector<uint8_t> tile_texels;
  uint64_t tiles_rewritten = 0;
  for (uint32_t level = 0; level < info.level_count; ++level) {
    const TexelRect tiles = affectedTiles(info, level, changed.rect);
    TESSERA_ASSIGN_OR_RETURN(LevelWindow window, decodeWindow(*archive, image, level, tiles));
    for (uint32_t row = changed.rect.y0; row < changed.rect.y1; ++row)
      std::memcpy(window.at(changed.rect.x0, row), changed.at(changed.rect.x0, row),
                  changed.texels.strideBytes());
    LevelChanges changes;
    for (uint32_t ty = tiles.y0; ty < tiles.y1; ++ty) {
      for (uint32_t tx = tiles.x0; tx < tiles.x1; ++tx) {
        cutFromWindow(window, info, level, tx, ty, tile_texels);
        TESSERA_ASSIGN_OR_RETURN(changes[uint64_t(ty) * info.tilesX(level) + tx],
                                 storeTile(tail, info, options, tile_texels, scratch,
                                           archive->tileName({image, level, tx, ty})));
        ++tiles_rewritten;
      }
    }
    TESSERA_TRY(rewriteLevel(tail, image, level, changes));
    if (level + 1 < info.level_count)
      changed = downsampleChanged(window, info, level, changed.rect);
    else
      refreshStatistics(tail.metadata(), image, window);
  }
  TESSERA_ASSIGN_OR_RETURN(UpdateReport report, tail.commit());
  report.tiles_rewritten = tiles_rewritten;
  return report;
}

}  // namespace tessera::detail
