#pragma once
// Archive internals shared by archive.cpp, region.cpp and verify.cpp.

#include <deque>
#include <future>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

#include <tessera/archive.h>
#include <tessera/procedural.h>

#include "format/directory.h"
#include "format/header.h"
#include "recent_parents.h"

namespace tessera {

struct Archive::Impl {
  std::shared_ptr<ByteSource> source;
  std::string name;
  detail::FileHeader header;
  std::vector<detail::ImageRecord> records;
  std::vector<ImageInfo> infos;
  std::string metadata_json;  ///< the metadata block as stored, "{}" when there is none
  /// The first min(header_region_bytes, file) bytes, read at open; blocks inside it cost no I/O.
  std::vector<uint8_t> header_region;

  /// Pages kept decoded; beyond this the oldest are dropped (a page is at most 1.5 MiB).
  static constexpr size_t kMaxCachedPages = 1024;
  /// Page indexes up to this size are read whole and verified; larger ones (terapixel levels)
  /// are read one 24-byte reference at a time, each page then verified by its own checksum.
  static constexpr uint64_t kWholePageIndexBytes = 65536;

  /// Directory pages an archive on a network source reads at open, at most (about an image of
  /// 16384 x 16384 at 256-px tiles, every level).
  static constexpr uint64_t kDirectoryAheadBytes = 256u << 10;

  static uint64_t pageKey(uint32_t image, uint32_t level, uint32_t page_index) {
    return (uint64_t(image) << 40) | (uint64_t(level) << 32) | page_index;
  }

  std::mutex cache_mutex;  // guards pages, page_order and page_indexes
  std::unordered_map<uint64_t, std::shared_ptr<const std::vector<TileEntry>>> pages;
  std::deque<uint64_t> page_order;  ///< insertion order of `pages`, for FIFO eviction
  /// Whole page indexes by (image, level) key; null entry means "read per reference".
  std::unordered_map<uint64_t, std::shared_ptr<const std::vector<detail::PageRef>>> page_indexes;

  /// Reads a block (from header_region when inside it) and verifies its checksum.
  Result<std::vector<uint8_t>> readBlock(const detail::BlockRef& block,
                                         const std::string& what) const;
  /// A directory page's entries by the rules of the file's minor version (kind 3 from 1.1 on).
  Result<std::vector<TileEntry>> decodeEntries(std::span<const uint8_t> bytes,
                                               const ImageInfo& info,
                                               const std::string& what) const;
  /// The page reference for a page of a level.
  Result<detail::PageRef> pageRef(uint32_t image, uint32_t level, uint32_t page_index);
  using PageResult = Result<std::shared_ptr<const std::vector<TileEntry>>>;
  /// The decoded entries of one directory page. A page another thread is reading is waited
  /// for, not read again: after a jump every loader thread wants the same pages at once, and
  /// over a network link each duplicate read costs a round trip and the page's bytes.
  PageResult page(uint32_t image, uint32_t level, uint32_t page_x, uint32_t page_y);
  /// Pages being read now, by key (under cache_mutex).
  std::unordered_map<uint64_t, std::shared_future<PageResult>> pages_loading;
  std::string tileName(const TileId& tile) const;
  /// Reads the directory pages of the coarsest levels, as many whole levels as fit
  /// `budget_bytes`, in one ByteSource::readEach and caches them (directory_ahead.cpp). Never
  /// fails: a page it could not read or verify is read again, and reported, by its first reader.
  void readDirectoryAhead(uint64_t budget_bytes);

  /// The section table (format 1.1) and its procedural directory (kind 2); length 0 when the
  /// archive has none.
  detail::BlockRef section_table;
  detail::BlockRef procedural_directory;
  /// The brush set and compositing of procedural tiles (Archive::procedural), loaded on the
  /// first procedural tile so that opening an archive reads no brush image, and a damaged brush
  /// block fails only the procedural tiles (each, naming the block), never open() or the baked
  /// tiles. Locked after cache_mutex is released, never inside it.
  std::mutex procedural_mutex;          // guards procedural_tiles; held while it loads (one load)
  mutable std::mutex compositor_mutex;  // guards tile_compositor
  std::shared_ptr<TileCompositor> tile_compositor;
  std::shared_ptr<const ProceduralTiles> procedural_tiles;

  /// Decoded parents of parent-coded (ptm) tiles for decodeTile without a parent (regions,
  /// verify, extract, the server). The loader passes its own decoded-tile cache instead.
  detail::RecentParents parents;
};

}  // namespace tessera
