// Archive::verify: every checksum and structural invariant of docs/format.md, reporting all
// faults rather than stopping at the first.
#include <tessera/archive.h>

#include <algorithm>
#include <set>
#include <tuple>

#include <fmt/format.h>

#include "archive_impl.h"

namespace tessera {

namespace {

struct Extent {
  uint64_t offset;
  uint64_t length;
  std::string what;
};

void addFault(VerifyReport& report, std::string message) {
  ++report.fault_count;
  if (report.faults.size() < VerifyReport::kMaxReportedFaults)
    report.faults.push_back(std::move(message));
}

// What verify carries from tile to tile.
struct TileChecks {
  VerifyReport& report;
  std::vector<Extent>& extents;
  CodecScratch scratch;
  /// Instance pages already checked, by (offset, length, checksum): several procedural entries
  /// may share one page (stored once), which is read, listed as an extent and counted once.
  std::set<std::tuple<uint64_t, uint32_t, uint64_t>> pages_seen;
};

// One tile's payload: read and checksummed; decoded (encoded) or composited (procedural)
// when `decode_payloads`, else a procedural page is still parsed and its brush references
// checked against the archive's brush set.
void verifyTile(const Archive& archive, const TileId& tile, const TileEntry& entry,
                bool decode_payloads, TileChecks& checks) {
  if (entry.kind == TileKind::kProcedural &&
      !checks.pages_seen.emplace(entry.offset_bytes, entry.length_bytes, entry.checksum).second)
    return;
  checks.extents.push_back({entry.offset_bytes, entry.length_bytes, archive.tileName(tile)});
  auto payload = archive.readPayload(tile, entry);
  ++checks.report.payloads_checked;
  if (!payload) {
    addFault(checks.report, payload.error().message);
    return;
  }
  checks.report.payload_bytes += payload->size();
  if (decode_payloads) {
    auto decoded = archive.decodeTile(tile, entry, *payload, &checks.scratch);
    if (!decoded) addFault(checks.report, decoded.error().message);
  } else if (entry.kind == TileKind::kProcedural) {
    auto tiles = archive.procedural();
    Result<void> checked = tiles ? (*tiles)->checkPage(archive, tile, entry, *payload)
                                 : Result<void>(forwardError(tiles));
    if (!checked) addFault(checks.report, checked.error().message);
  }
}

}  // namespace

VerifyReport Archive::verify(bool decode_payloads,
                             const std::function<void(uint64_t, uint64_t)>& on_progress) const {
  VerifyReport report;
  Impl& impl = *impl_;
  std::vector<Extent> extents;
  extents.push_back({0, detail::kHeaderBytes, "header"});
  extents.push_back(
      {impl.header.root.offset_bytes, impl.header.root.length_bytes, "root directory"});
  if (impl.header.metadata.length_bytes)
    extents.push_back(
        {impl.header.metadata.offset_bytes, impl.header.metadata.length_bytes, "metadata"});
  if (impl.section_table.length_bytes)
    extents.push_back(
        {impl.section_table.offset_bytes, impl.section_table.length_bytes, "section table"});
  if (impl.procedural_directory.length_bytes) {
    extents.push_back({impl.procedural_directory.offset_bytes,
                       impl.procedural_directory.length_bytes, "procedural directory"});
    // Every brush image and the height layer, read, checksummed and decoded once here.
    auto tiles = procedural();
    if (!tiles) addFault(report, tiles.error().message);
  }
  uint64_t levels_total = 0, levels_done = 0;
  for (const ImageInfo& info : impl.infos) levels_total += info.level_count;
  TileChecks checks{report, extents, {}, {}};

  for (uint32_t image = 0; image < impl.infos.size(); ++image) {
    const ImageInfo& info = impl.infos[image];
    for (uint32_t level = 0; level < info.level_count; ++level) {
      const detail::BlockRef& index_block = impl.records[image].levels[level].page_index;
      std::string level_name = fmt::format("image {} level {}", image, level);
      std::vector<detail::PageRef> refs;
      uint64_t page_count = uint64_t(detail::pagesX(info, level)) * detail::pagesY(info, level);
      if (index_block.length_bytes == 0) {
        refs.resize(page_count);
      } else {
        extents.push_back(
            {index_block.offset_bytes, index_block.length_bytes, level_name + " page index"});
        auto bytes = impl.readBlock(index_block, level_name + " page index");
        if (!bytes) {
          addFault(report, bytes.error().message);
          continue;
        }
        auto decoded = detail::decodePageIndex(*bytes, info, level, impl.header.file_bytes,
                                               impl.name + ": " + level_name + " page index");
        if (!decoded) {
          addFault(report, decoded.error().message);
          continue;
        }
        refs = std::move(*decoded);
      }
      uint64_t level_payload_bytes = 0;
      uint32_t pages_x = detail::pagesX(info, level);
      for (uint32_t p = 0; p < refs.size(); ++p) {
        uint32_t page_x = p % pages_x, page_y = p / pages_x;
        detail::PageGeometry geometry = detail::pageGeometry(info, level, page_x, page_y);
        std::string page_name = fmt::format("{} page ({},{})", level_name, page_x, page_y);
        ++report.pages_checked;
        std::vector<TileEntry> entries(size_t(geometry.columns) * geometry.rows);
        if (refs[p].length_bytes) {
          extents.push_back({refs[p].offset_bytes, refs[p].length_bytes, page_name});
          auto bytes = impl.readBlock(refs[p], page_name);
          if (!bytes) {
            addFault(report, bytes.error().message);
            continue;
          }
          auto decoded = impl.decodeEntries(*bytes, info, impl.name + ": " + page_name);
          if (!decoded) {
            addFault(report, decoded.error().message);
            continue;
          }
          entries = std::move(*decoded);
        }
        for (size_t i = 0; i < entries.size(); ++i) {
          const TileEntry& entry = entries[i];
          TileId tile{image, level, geometry.first_tile_x + uint32_t(i % geometry.columns),
                      geometry.first_tile_y + uint32_t(i / geometry.columns)};
          ++report.tiles_checked;
          if (!entry.hasPayload()) continue;
          level_payload_bytes += entry.length_bytes;
          verifyTile(*this, tile, entry, decode_payloads, checks);
        }
      }
      if (level_payload_bytes != impl.records[image].levels[level].payload_bytes)
        addFault(
            report,
            fmt::format("{}: {} records {} payload bytes, its tiles hold {}", impl.name, level_name,
                        impl.records[image].levels[level].payload_bytes, level_payload_bytes));
      if (on_progress) on_progress(++levels_done, levels_total);
    }
  }

  std::sort(extents.begin(), extents.end(),
            [](const Extent& a, const Extent& b) { return a.offset < b.offset; });
  for (size_t i = 1; i < extents.size(); ++i) {
    const Extent& prev = extents[i - 1];
    if (extents[i].offset < prev.offset + prev.length)
      addFault(report, fmt::format("{}: {} at offset {} overlaps {} ending at {}", impl.name,
                                   extents[i].what, extents[i].offset, prev.what,
                                   prev.offset + prev.length));
  }
  return report;
}

}  // namespace tessera
