// Reading the directory ahead at open on a source whose reads are network round trips: the
// pages a first view needs would otherwise be read one level at a time, as the loaders reach
// them, each a round trip before its tiles (docs/remote.md, "The first view").
#include <algorithm>
#include <atomic>
#include <cstring>

#include <fmt/format.h>

#include "archive_impl.h"
#include "format/checksum.h"

namespace tessera {

namespace {

/// Directory pages lie together after the payloads (docs/format.md, "File layout"): pages
/// closer than this are read as one range, so a server without multi-range requests still
/// sends the directory in one answer.
constexpr uint64_t kDirectoryGapBytes = 16 * 1024;

/// Cached pages the read-ahead fills at most, leaving the rest of the page cache to reads.
constexpr size_t kMaxPagesAhead = Archive::Impl::kMaxCachedPages / 2;

struct PageAhead {
  uint64_t key = 0;
  uint32_t image = 0;
  uint32_t level = 0;
  uint32_t page_x = 0;
  uint32_t page_y = 0;
  detail::PageRef ref;
  size_t run = 0;  ///< index of the range holding it
};

}  // namespace

void Archive::Impl::readDirectoryAhead(uint64_t budget_bytes) {
  // The coarsest levels first (a first view shows the whole image), each level whole or not at
  // all, and only levels whose page index is in the header region: finding a page costs no I/O.
  std::vector<PageAhead> wanted;
  uint64_t total_bytes = 0;
  for (uint32_t image = 0; image < records.size(); ++image) {
    const ImageInfo& info = infos[image];
    for (uint32_t level = info.level_count; level-- > 0;) {
      const detail::BlockRef& index = records[image].levels[level].page_index;
      if (index.length_bytes == 0) continue;
      if (index.offset_bytes + index.length_bytes > header_region.size()) break;
      std::vector<PageAhead> level_pages;
      uint64_t level_bytes = 0;
      const uint32_t pages_x = detail::pagesX(info, level), pages_y = detail::pagesY(info, level);
      for (uint32_t y = 0; y < pages_y; ++y)
        for (uint32_t x = 0; x < pages_x; ++x) {
          Result<detail::PageRef> ref = pageRef(image, level, y * pages_x + x);
          if (!ref) return;  // the open's directory is damaged: reads report it, tile by tile
          if (ref->length_bytes == 0) continue;
          level_pages.push_back(
              {pageKey(image, level, y * pages_x + x), image, level, x, y, *ref, 0});
          level_bytes += ref->length_bytes;
        }
      if (total_bytes + level_bytes > budget_bytes ||
          wanted.size() + level_pages.size() > kMaxPagesAhead)
        break;
      total_bytes += level_bytes;
      wanted.insert(wanted.end(), level_pages.begin(), level_pages.end());
    }
  }
  if (wanted.empty()) return;
  std::sort(wanted.begin(), wanted.end(), [](const PageAhead& a, const PageAhead& b) {
    return a.ref.offset_bytes < b.ref.offset_bytes;
  });
  std::vector<ByteRange> runs;
  for (PageAhead& page : wanted) {
    const uint64_t end = page.ref.offset_bytes + page.ref.length_bytes;
    if (runs.empty() || page.ref.offset_bytes > runs.back().offset_bytes +
                                                    runs.back().length_bytes + kDirectoryGapBytes) {
      runs.push_back({page.ref.offset_bytes, page.ref.length_bytes, nullptr});
    } else {
      runs.back().length_bytes =
          std::max(runs.back().offset_bytes + runs.back().length_bytes, end) -
          runs.back().offset_bytes;
    }
    page.run = runs.size() - 1;
  }
  std::vector<std::vector<uint8_t>> buffers(runs.size());
  for (size_t i = 0; i < runs.size(); ++i) {
    buffers[i].resize(runs[i].length_bytes);
    runs[i].out = buffers[i].data();
  }
  const std::atomic<bool> never{false};
  const std::vector<Result<void>> read = source->readEach(runs, never);
  // A page whose range failed, or that fails its checksum or checks, is left out: its first
  // reader reads it again and reports what is wrong, naming the page.
  for (const PageAhead& page : wanted) {
    if (!read[page.run]) continue;
    const auto bytes =
        std::span<const uint8_t>(buffers[page.run])
            .subspan(page.ref.offset_bytes - runs[page.run].offset_bytes, page.ref.length_bytes);
    if (detail::checksum64(bytes) != page.ref.checksum) continue;
    Result<std::vector<TileEntry>> entries =
        decodeEntries(bytes, infos[page.image],
                      fmt::format("{}: image {} level {} page ({},{})", name, page.image,
                                  page.level, page.page_x, page.page_y));
    if (!entries) continue;
    std::lock_guard lock(cache_mutex);
    if (pages.emplace(page.key, std::make_shared<const std::vector<TileEntry>>(std::move(*entries)))
            .second)
      page_order.push_back(page.key);
  }
}

}  // namespace tessera
