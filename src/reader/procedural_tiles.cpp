// ProceduralTiles: the brush set of a format 1.1 archive, and procedural tiles composited from
// their instance pages (docs/format.md, "Procedural tiles").
#include <tessera/procedural.h>

#include <mutex>
#include <unordered_map>

#include <fmt/format.h>

#include <tessera/archive.h>

#include "codecs/decode.h"
#include "format/checksum.h"
#include "format/directory.h"
#include "format/header.h"
#include "format/procedural.h"
#include "format/sections.h"

namespace tessera {

using namespace detail;

struct ProceduralTiles::Impl {
  FileHeader header;
  std::vector<ImageRecord> records;
  ProceduralDirectory directory;
  std::shared_ptr<const BrushSet> brushes;
  uint64_t stored_bytes = 0;
  std::string name;

  /// A page's instances (and clips when `clips` is set) after checking that the tile's image
  /// is the procedural one, the page's length and checksum, its structure and that every
  /// instance names a stored brush: whatever fails fails the tile (kCorrupt, naming it).
  Result<std::vector<BrushInstance>> decodePage(const TileId& tile, const TileEntry& entry,
                                                std::span<const uint8_t> page,
                                                const std::string& what,
                                                std::vector<TileClip>* clips) const {
    if (tile.image != directory.image)
      return fail(ErrorCode::kCorrupt, what + ": procedural, but its image has no brush set");
    if (page.size() != entry.length_bytes || checksum64(page) != entry.checksum)
      return fail(ErrorCode::kCorrupt, fmt::format("{}: instance page checksum mismatch at "
                                                   "offset {}",
                                                   what, entry.offset_bytes));
    return decodeInstancePage(page, uint32_t(directory.brushes.size()), what, clips);
  }
};

namespace {

Result<std::vector<uint8_t>> readVerified(const ByteSource& source, const BlockRef& block,
                                          const std::string& what) {
  std::vector<uint8_t> bytes(block.length_bytes);
  TESSERA_TRY(source.read(block.offset_bytes, bytes));
  if (checksum64(bytes) != block.checksum)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{} checksum mismatch at offset {}", what, block.offset_bytes));
  return bytes;
}

Result<Image> readPicture(const ByteSource& source, const ProceduralImageRecord& record,
                          const std::string& what) {
  TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> payload, readVerified(source, record.block, what));
  Image image(record.width_px, record.height_px, record.channels);
  Result<void> decoded = decodeTile(record.codec, payload, image);
  if (!decoded) return fail(decoded.error().code, what + ": " + decoded.error().message);
  return image;
}

}  // namespace

ProceduralTiles::ProceduralTiles(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
ProceduralTiles::~ProceduralTiles() = default;

uint32_t ProceduralTiles::image() const {
  return impl_->directory.image;
}
const BrushSet& ProceduralTiles::brushSet() const {
  return *impl_->brushes;
}
uint64_t ProceduralTiles::storedBrushBytes() const {
  return impl_->stored_bytes;
}

Result<std::shared_ptr<const ProceduralTiles>> ProceduralTiles::open(const Archive& archive) {
  const ByteSource& source = archive.source();
  auto impl = std::make_unique<Impl>();
  impl->name = archive.name();
  std::vector<uint8_t> header_bytes(kHeaderBytes);
  TESSERA_TRY(source.read(0, header_bytes));
  TESSERA_ASSIGN_OR_RETURN(impl->header, decodeHeader(header_bytes, archive.name()));
  TESSERA_ASSIGN_OR_RETURN(const BlockRef table,
                           decodeSectionTableRef(header_bytes, impl->header, archive.name()));
  std::vector<SectionEntry> sections;
  if (table.length_bytes != 0) {
    TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> table_bytes,
                             readVerified(source, table, archive.name() + ": section table"));
    TESSERA_ASSIGN_OR_RETURN(sections,
                             decodeSectionTable(table_bytes, impl->header, archive.name()));
  }
  TESSERA_ASSIGN_OR_RETURN(BlockRef block, decodeProceduralRef(sections, archive.name()));
  if (block.length_bytes == 0)
    return fail(ErrorCode::kNotFound, archive.name() + ": the archive has no procedural tiles");
  TESSERA_ASSIGN_OR_RETURN(
      std::vector<uint8_t> root,
      readVerified(source, impl->header.root, archive.name() + ": root directory"));
  TESSERA_ASSIGN_OR_RETURN(impl->records, decodeRootDirectory(root, impl->header, archive.name()));
  TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes,
                           readVerified(source, block, archive.name() + ": procedural directory"));
  TESSERA_ASSIGN_OR_RETURN(
      impl->directory,
      decodeProceduralDirectory(bytes, impl->header, impl->header.image_count, archive.name()));
  const ProceduralDirectory& directory = impl->directory;
  if (impl->records[directory.image].info.channels != 4)
    return fail(
        ErrorCode::kCorrupt,
        fmt::format("{}: procedural image {} has {} channels; procedural tiles are RGBA",
                    archive.name(), directory.image, impl->records[directory.image].info.channels));
  std::vector<Brush> brushes;
  for (size_t b = 0; b < directory.brushes.size(); ++b) {
    const ProceduralBrushRecord& record = directory.brushes[b];
    Brush brush;
    brush.name = fmt::format("brush {}", b);
    brush.blend = record.blend;
    brush.mask = record.mask;
    brush.mask_low = record.mask_low;
    brush.mask_high = record.mask_high;
    for (uint32_t i = record.image_first; i < record.image_first + record.image_count; ++i) {
      TESSERA_ASSIGN_OR_RETURN(
          Image image, readPicture(source, directory.images[i],
                                   fmt::format("{}: brush {} image {}", archive.name(), b, i)));
      brush.images.push_back(std::move(image));
    }
    brushes.push_back(std::move(brush));
  }
  for (const ProceduralImageRecord& image : directory.images)
    impl->stored_bytes += image.block.length_bytes;
  UnderlyingLayer layer;
  if (directory.height_layer.width_px != 0) {
    TESSERA_ASSIGN_OR_RETURN(layer.height, readPicture(source, directory.height_layer,
                                                       archive.name() + ": height layer"));
    impl->stored_bytes += directory.height_layer.block.length_bytes;
  }
  const ImageInfo& info = impl->records[directory.image].info;
  Result<std::shared_ptr<const BrushSet>> set =
      BrushSet::prepare(std::move(brushes), std::move(layer), info.width_px, info.height_px);
  if (!set) return fail(ErrorCode::kCorrupt, archive.name() + ": " + set.error().message);
  impl->brushes = std::move(*set);
  return std::shared_ptr<const ProceduralTiles>(new ProceduralTiles(std::move(impl)));
}

Result<void> ProceduralTiles::checkPage(const Archive& archive, const TileId& tile,
                                        const TileEntry& entry,
                                        std::span<const uint8_t> page) const {
  TESSERA_TRY(impl_->decodePage(tile, entry, page, archive.tileName(tile), nullptr));
  return {};
}

Result<void> ProceduralTiles::compositeTile(const Archive& archive, const TileId& tile,
                                            const TileEntry& entry, Image& out) const {
  if (entry.kind != TileKind::kProcedural)
    return fail(ErrorCode::kInvalidArgument, archive.tileName(tile) + ": not a procedural tile");
  std::vector<uint8_t> page(entry.length_bytes);
  TESSERA_TRY(archive.source().read(entry.offset_bytes, page));
  return compositePage(archive, tile, entry, page, out);
}

Result<void> ProceduralTiles::compositePage(const Archive& archive, const TileId& tile,
                                            const TileEntry& entry, std::span<const uint8_t> page,
                                            Image& out) const {
  const std::string what = archive.tileName(tile);
  std::vector<TileClip> clips;
  TESSERA_ASSIGN_OR_RETURN(std::vector<BrushInstance> instances,
                           impl_->decodePage(tile, entry, page, what, &clips));
  const ImageInfo& info = impl_->records[tile.image].info;
  TileGeometry geometry{tile.level,     tile.x,        tile.y,        info.tile_size_px,
                        info.border_px, info.width_px, info.height_px};
  const std::shared_ptr<TileCompositor> compositor = archive.tileCompositor();
  Result<void> composited =
      compositor ? compositor->composite(impl_->brushes, geometry, instances, clips, out)
                 : tessera::compositeTile(*impl_->brushes, geometry, instances, out, clips);
  if (!composited) return fail(ErrorCode::kCorrupt, what + ": " + composited.error().message);
  return {};
}

}  // namespace tessera
