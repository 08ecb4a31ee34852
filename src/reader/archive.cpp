#include <tessera/archive.h>

#include <algorithm>
#include <cstring>
#include <optional>

#include <fmt/format.h>

#include "archive_impl.h"
#include "codecs/decode.h"
#include "format/checksum.h"
#include "format/metadata.h"
#include "format/procedural.h"
#include "format/sections.h"
#include "reader/parent_chain.h"

namespace tessera {

using detail::BlockRef;
using detail::PageRef;

namespace {

uint64_t levelKey(uint32_t image, uint32_t level) {
  return (uint64_t(image) << 8) | level;
}

}  // namespace

std::string Archive::tileName(const TileId& tile) const {
  return impl_->tileName(tile);
}

std::string Archive::Impl::tileName(const TileId& tile) const {
  if (records.size() == 1)
    return fmt::format("{}: tile ({},{},{})", name, tile.level, tile.x, tile.y);
  return fmt::format("{}: image {} tile ({},{},{})", name, tile.image, tile.level, tile.x, tile.y);
}

Result<std::vector<uint8_t>> Archive::Impl::readBlock(const BlockRef& block,
                                                      const std::string& what) const {
  std::vector<uint8_t> bytes(block.length_bytes);
  if (block.offset_bytes + block.length_bytes <= header_region.size()) {
    std::memcpy(bytes.data(), header_region.data() + block.offset_bytes, bytes.size());
  } else {
    TESSERA_TRY(source->read(block.offset_bytes, bytes));
  }
  uint64_t actual = detail::checksum64(bytes);
  if (actual != block.checksum)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: {} checksum mismatch at offset {} (stored {:016x}, computed "
                            "{:016x})",
                            name, what, block.offset_bytes, block.checksum, actual));
  return bytes;
}

Result<PageRef> Archive::Impl::pageRef(uint32_t image, uint32_t level, uint32_t page_index) {
  const ImageInfo& info = infos[image];
  const BlockRef& index_block = records[image].levels[level].page_index;
  if (index_block.length_bytes == 0) return PageRef{};
  std::string what = fmt::format("{}: image {} level {} page index", name, image, level);
  bool whole = index_block.length_bytes <= kWholePageIndexBytes ||
               index_block.offset_bytes + index_block.length_bytes <= header_region.size();
  if (!whole) {
    uint8_t ref_bytes[detail::kPageRefBytes];
    TESSERA_TRY(source->read(
        index_block.offset_bytes + uint64_t(page_index) * detail::kPageRefBytes, ref_bytes));
    return detail::decodePageRef(ref_bytes, info, level, page_index, header.file_bytes, what);
  }
  uint64_t key = levelKey(image, level);
  {
    std::lock_guard lock(cache_mutex);
    auto it = page_indexes.find(key);
    if (it != page_indexes.end()) return (*it->second)[page_index];
  }
  TESSERA_ASSIGN_OR_RETURN(
      std::vector<uint8_t> bytes,
      readBlock(index_block, fmt::format("image {} level {} page index", image, level)));
  TESSERA_ASSIGN_OR_RETURN(std::vector<PageRef> refs,
                           detail::decodePageIndex(bytes, info, level, header.file_bytes, what));
  auto shared = std::make_shared<const std::vector<PageRef>>(std::move(refs));
  std::lock_guard lock(cache_mutex);
  page_indexes.emplace(key, shared);
  return (*shared)[page_index];
}

Result<std::vector<TileEntry>> Archive::Impl::decodeEntries(std::span<const uint8_t> bytes,
                                                            const ImageInfo& info,
                                                            const std::string& what) const {
  // Kind-3 (procedural) entries are valid from minor 1 on; the 1.1 decoder applies the 1.0
  // rules to everything else.
  if (header.version_minor >= detail::kProceduralMinorVersion)
    return detail::decodeTileEntriesProcedural(bytes, info, header, what);
  return detail::decodeTileEntries(bytes, info, header, what);
}

Archive::Impl::PageResult Archive::Impl::page(uint32_t image, uint32_t level, uint32_t page_x,
                                              uint32_t page_y) {
  const ImageInfo& info = infos[image];
  uint32_t page_index = page_y * detail::pagesX(info, level) + page_x;
  uint64_t key = pageKey(image, level, page_index);
  std::promise<PageResult> reading;
  {
    std::unique_lock lock(cache_mutex);
    auto it = pages.find(key);
    if (it != pages.end()) return it->second;
    auto loading = pages_loading.find(key);
    if (loading != pages_loading.end()) {
      std::shared_future<PageResult> pending = loading->second;
      lock.unlock();
      return pending.get();
    }
    pages_loading.emplace(key, reading.get_future().share());
  }
  auto read = [&]() -> PageResult {
    TESSERA_ASSIGN_OR_RETURN(PageRef ref, pageRef(image, level, page_index));
    detail::PageGeometry geometry = detail::pageGeometry(info, level, page_x, page_y);
    std::vector<TileEntry> entries;
    if (ref.length_bytes == 0) {
      entries.resize(size_t(geometry.columns) * geometry.rows);
    } else {
      std::string what =
          fmt::format("image {} level {} page ({},{})", image, level, page_x, page_y);
      TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, readBlock(ref, what));
      TESSERA_ASSIGN_OR_RETURN(entries, decodeEntries(bytes, info, name + ": " + what));
    }
    return std::make_shared<const std::vector<TileEntry>>(std::move(entries));
  };
  PageResult result = read();
  {
    std::lock_guard lock(cache_mutex);
    pages_loading.erase(key);
    if (result && pages.emplace(key, *result).second) {
      page_order.push_back(key);
      if (page_order.size() > kMaxCachedPages) {
        pages.erase(page_order.front());
        page_order.pop_front();
      }
    }
  }
  reading.set_value(result);
  return result;
}

namespace {

// The header at offset 0, or, when a torn write left it invalid, the copy an update syncs as
// the file's last 128 bytes before it rewrites offset 0 (docs/format.md, "Appended
// versions"). The copy counts only where it describes exactly this file.
Result<detail::FileHeader> readCommittedHeader(const ByteSource& source,
                                               std::span<const uint8_t> header_region,
                                               uint64_t size) {
  Result<detail::FileHeader> header = detail::decodeHeader(header_region, source.name());
  if (header || header.error().code != ErrorCode::kCorrupt || size < 2 * detail::kHeaderBytes)
    return header;
  std::vector<uint8_t> copy_bytes(detail::kHeaderBytes);
  if (!source.read(size - detail::kHeaderBytes, copy_bytes)) return header;
  Result<detail::FileHeader> copy =
      detail::decodeHeader(copy_bytes, source.name() + ": header copy");
  if (!copy || copy->file_bytes != size) return header;
  return copy;
}

}  // namespace

Archive::Archive(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Archive::~Archive() = default;

Result<std::shared_ptr<Archive>> Archive::open(std::shared_ptr<ByteSource> source) {
  auto impl = std::make_unique<Impl>();
  impl->name = source->name();
  impl->source = source;
  const std::string& name = impl->name;
  uint64_t size = source->sizeBytes();
  if (size == 0) return fail(ErrorCode::kCorrupt, name + ": empty file, not a Tessera archive");
  impl->header_region.resize(std::min<uint64_t>(size, detail::kHeaderRegionBytes));
  TESSERA_TRY(source->read(0, impl->header_region));
  TESSERA_ASSIGN_OR_RETURN(impl->header, readCommittedHeader(*source, impl->header_region, size));
  const detail::FileHeader& header = impl->header;
  // Bytes past file_bytes are the uncommitted tail of an interrupted update (docs/format.md,
  // "Appended versions"): never referenced, so ignored.
  if (header.file_bytes > size)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: header records {} bytes but the file has {} (truncated)", name,
                            header.file_bytes, size));
  if (header.header_region_bytes > impl->header_region.size()) {
    // A writer may use a larger header region; read the rest once so its blocks are free too.
    size_t old_size = impl->header_region.size();
    impl->header_region.resize(header.header_region_bytes);
    TESSERA_TRY(source->read(old_size, std::span(impl->header_region).subspan(old_size)));
  }
  TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> root_bytes,
                           impl->readBlock(header.root, "root directory"));
  TESSERA_ASSIGN_OR_RETURN(impl->records, detail::decodeRootDirectory(root_bytes, header, name));
  detail::ArchiveMetadata metadata;
  metadata.image_names.resize(impl->records.size());
  if (header.metadata.length_bytes > 0) {
    TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> json_bytes,
                             impl->readBlock(header.metadata, "metadata"));
    TESSERA_ASSIGN_OR_RETURN(metadata,
                             detail::parseMetadata(json_bytes, impl->records.size(), name));
  }
  impl->metadata_json = std::move(metadata.json);
  TESSERA_ASSIGN_OR_RETURN(impl->section_table,
                           detail::decodeSectionTableRef(impl->header_region, header, name));
  if (impl->section_table.length_bytes != 0) {
    TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> table_bytes,
                             impl->readBlock(impl->section_table, "section table"));
    TESSERA_ASSIGN_OR_RETURN(std::vector<detail::SectionEntry> entries,
                             detail::decodeSectionTable(table_bytes, header, name));
    // Other kinds (a scene) are other readers' business; the image reader skips them.
    TESSERA_ASSIGN_OR_RETURN(impl->procedural_directory,
                             detail::decodeProceduralRef(entries, name));
  }
  for (size_t i = 0; i < impl->records.size(); ++i) {
    ImageInfo info = impl->records[i].info;
    info.name = std::move(metadata.image_names[i]);
    impl->infos.push_back(std::move(info));
  }
  // Over a network the first view's directory pages come in one request now rather than a
  // round trip per level later (docs/remote.md, "The first view").
  if (source->readsRangesTogether()) impl->readDirectoryAhead(Impl::kDirectoryAheadBytes);
  return std::shared_ptr<Archive>(new Archive(std::move(impl)));
}

const std::string& Archive::name() const {
  return impl_->name;
}
const std::vector<ImageInfo>& Archive::images() const {
  return impl_->infos;
}
const std::string& Archive::metadataJson() const {
  return impl_->metadata_json;
}
uint64_t Archive::fileBytes() const {
  return impl_->header.file_bytes;
}
const ByteSource& Archive::source() const {
  return *impl_->source;
}

Result<TileEntry> Archive::tileEntry(const TileId& tile) const {
  if (tile.image >= impl_->infos.size())
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: no image {} (archive has {})", impl_->name, tile.image,
                            impl_->infos.size()));
  const ImageInfo& info = impl_->infos[tile.image];
  if (tile.level >= info.level_count || tile.x >= info.tilesX(tile.level) ||
      tile.y >= info.tilesY(tile.level))
    return fail(ErrorCode::kInvalidArgument, fmt::format("{} is outside the image ({} levels)",
                                                         impl_->tileName(tile), info.level_count));
  uint32_t shift = info.page_tiles_log2;
  TESSERA_ASSIGN_OR_RETURN(auto entries,
                           impl_->page(tile.image, tile.level, tile.x >> shift, tile.y >> shift));
  detail::PageGeometry geometry =
      detail::pageGeometry(info, tile.level, tile.x >> shift, tile.y >> shift);
  return (*entries)[size_t(tile.y - geometry.first_tile_y) * geometry.columns +
                    (tile.x - geometry.first_tile_x)];
}

std::optional<TileEntry> Archive::tileEntryIfCached(const TileId& tile) const {
  if (tile.image >= impl_->infos.size()) return std::nullopt;
  const ImageInfo& info = impl_->infos[tile.image];
  if (tile.level >= info.level_count || tile.x >= info.tilesX(tile.level) ||
      tile.y >= info.tilesY(tile.level))
    return std::nullopt;
  const uint32_t shift = info.page_tiles_log2;
  const uint32_t page_x = tile.x >> shift, page_y = tile.y >> shift;
  const uint64_t key =
      Impl::pageKey(tile.image, tile.level, page_y * detail::pagesX(info, tile.level) + page_x);
  std::shared_ptr<const std::vector<TileEntry>> entries;
  {
    std::lock_guard lock(impl_->cache_mutex);
    auto it = impl_->pages.find(key);
    if (it == impl_->pages.end()) return std::nullopt;
    entries = it->second;
  }
  detail::PageGeometry geometry = detail::pageGeometry(info, tile.level, page_x, page_y);
  return (*entries)[size_t(tile.y - geometry.first_tile_y) * geometry.columns +
                    (tile.x - geometry.first_tile_x)];
}

Result<void> Archive::verifyPayload(const TileId& tile, const TileEntry& entry,
                                    std::span<const uint8_t> payload) const {
  if (payload.size() != entry.length_bytes)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{} payload of {} bytes, entry says {}", impl_->tileName(tile),
                            payload.size(), entry.length_bytes));
  uint64_t actual = detail::checksum64(payload);
  if (actual != entry.checksum)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{} checksum mismatch at offset {} (stored {:016x}, computed {:016x})",
                            impl_->tileName(tile), entry.offset_bytes, entry.checksum, actual));
  return {};
}

Result<std::vector<uint8_t>> Archive::readPayload(const TileId& tile,
                                                  const TileEntry& entry) const {
  TESSERA_CHECK(entry.hasPayload()) << "readPayload on a tile without payload";
  std::vector<uint8_t> payload(entry.length_bytes);
  TESSERA_TRY(impl_->source->read(entry.offset_bytes, payload));
  TESSERA_TRY(verifyPayload(tile, entry, payload));
  return payload;
}

Result<Image> Archive::decodeTile(const TileId& tile, const TileEntry& entry,
                                  std::span<const uint8_t> payload, CodecScratch* scratch) const {
  Image image;
  TESSERA_TRY(decodeTileInto(tile, entry, payload, image, scratch));
  return image;
}

Result<void> Archive::decodeTileInto(const TileId& tile, const TileEntry& entry,
                                     std::span<const uint8_t> payload, Image& image,
                                     CodecScratch* scratch) const {
  return decodeWithParent(tile, entry, payload, image, nullptr, scratch);
}

Result<void> Archive::decodeTileInto(const TileId& tile, const TileEntry& entry,
                                     std::span<const uint8_t> payload, Image& image,
                                     const Image& parent, CodecScratch* scratch) const {
  return decodeWithParent(tile, entry, payload, image, &parent, scratch);
}

Result<std::shared_ptr<const Image>> Archive::decodedParent(const TileId& tile,
                                                            CodecScratch* scratch) const {
  return detail::decodeParent(*this, tile, impl_->parents, scratch);
}

Result<void> Archive::decodeWithParent(const TileId& tile, const TileEntry& entry,
                                       std::span<const uint8_t> payload, Image& image,
                                       const Image* parent, CodecScratch* scratch) const {
  const ImageInfo& info = impl_->infos.at(tile.image);
  uint32_t side = info.storedTileSidePx();
  image.width_px = side;
  image.height_px = side;
  image.channels = info.channels;
  image.sample_type = info.sample_type;
  image.texels.resize(info.storedTileBytes());
  switch (entry.kind) {
    case TileKind::kEmpty: std::fill(image.texels.begin(), image.texels.end(), uint8_t{0}); break;
    case TileKind::kUniform: {
      uint8_t colour[4];
      for (uint32_t c = 0; c < 4; ++c) colour[c] = uint8_t(entry.uniform_rgba >> (8 * c));
      // One texel, then copies of what is filled so far: a few large copies, not one per texel.
      std::span<uint8_t> texels(image.texels);
      size_t filled = std::min<size_t>(info.channels, texels.size());
      std::memcpy(texels.data(), colour, filled);
      while (filled < texels.size()) {
        size_t copy = std::min(filled, texels.size() - filled);
        std::memcpy(texels.data() + filled, texels.data(), copy);
        filled += copy;
      }
      break;
    }
    case TileKind::kEncoded: {
      const detail::CodecDecoder* codec = detail::findDecoder(entry.codec);
      if (!codec)
        return fail(ErrorCode::kUnsupported,
                    fmt::format("{}: codec {} is not supported by this build",
                                impl_->tileName(tile), codecName(entry.codec)));
      std::optional<detail::ParentTexels> parent_texels;
      std::shared_ptr<const Image> owned_parent;
      if (codecNeedsParent(entry.codec) && tile.level + 1 < info.level_count) {
        if (parent == nullptr) {
          TESSERA_ASSIGN_OR_RETURN(owned_parent, decodedParent(tile, scratch));
          parent = owned_parent.get();
        }
        if (parent->width_px != side || parent->height_px != side ||
            parent->channels != info.channels ||
            parent->texels.size() != size_t(side) * side * info.channels)
          return fail(ErrorCode::kInvalidArgument,
                      fmt::format("{}: parent tile given as {}x{}x{}, expected {}x{}x{}",
                                  impl_->tileName(tile), parent->width_px, parent->height_px,
                                  parent->channels, side, side, info.channels));
        parent_texels = detail::ParentTexels{parent->view(), tile.x & 1, tile.y & 1,
                                             info.tile_size_px, info.border_px};
      }
      Result<void> decoded = detail::decodeTile(entry.codec, payload, image,
                                                parent_texels ? &*parent_texels : nullptr, scratch);
      if (!decoded)
        return fail(decoded.error().code,
                    fmt::format("{}: {}", impl_->tileName(tile), decoded.error().message));
      break;
    }
    case TileKind::kProcedural: {
      TESSERA_ASSIGN_OR_RETURN(std::shared_ptr<const ProceduralTiles> tiles, procedural());
      return tiles->compositePage(*this, tile, entry, payload, image);
    }
  }
  return {};
}

void Archive::setTileCompositor(std::shared_ptr<TileCompositor> compositor) {
  std::lock_guard lock(impl_->compositor_mutex);
  impl_->tile_compositor = std::move(compositor);
}

std::shared_ptr<TileCompositor> Archive::tileCompositor() const {
  std::lock_guard lock(impl_->compositor_mutex);
  return impl_->tile_compositor;
}

Result<std::shared_ptr<const ProceduralTiles>> Archive::procedural() const {
  std::lock_guard lock(impl_->procedural_mutex);
  if (impl_->procedural_tiles) return impl_->procedural_tiles;
  if (impl_->procedural_directory.length_bytes == 0)
    return fail(ErrorCode::kNotFound, impl_->name + ": the archive has no procedural directory");
  // Not cached on failure: a transient read error (a remote source) is retried by the next
  // procedural tile; a damaged block fails each of them with the same message.
  TESSERA_ASSIGN_OR_RETURN(impl_->procedural_tiles, ProceduralTiles::open(*this));
  return impl_->procedural_tiles;
}

Result<Image> Archive::readTile(const TileId& tile, CodecScratch* scratch) const {
  TESSERA_ASSIGN_OR_RETURN(TileEntry entry, tileEntry(tile));
  std::vector<uint8_t> payload;
  if (entry.hasPayload()) {
    TESSERA_ASSIGN_OR_RETURN(payload, readPayload(tile, entry));
  }
  return decodeTile(tile, entry, payload, scratch);
}

}  // namespace tessera
