#include "format/coverage_hints.h"

#include <cmath>
#include <cstring>

#include <fmt/format.h>

#include <tessera/check.h>

#include "format/byte_io.h"

namespace tessera::detail {

namespace {

constexpr uint8_t kMagic[4] = {'T', 'C', 'V', 'H'};
constexpr uint16_t kVersion = 1;

Result<void> checkGrid(const CoverageHints& h, const std::string& what) {
  auto bad = [&](const std::string& problem) {
    return fail(ErrorCode::kCorrupt, fmt::format("{}: {}", what, problem));
  };
  if (h.up_axis > 2) return bad(fmt::format("up axis {} is not 0, 1 or 2", h.up_axis));
  if (h.cells_u < 1 || h.cells_v < 1 || h.cells_u > kMaxHintCellsPerAxis ||
      h.cells_v > kMaxHintCellsPerAxis || uint64_t(h.cells_u) * h.cells_v > kMaxHintCells)
    return bad(fmt::format("grid of {} x {} cells, expected 1..{} per axis and at most {}",
                           h.cells_u, h.cells_v, kMaxHintCellsPerAxis, kMaxHintCells));
  if (!std::isfinite(h.origin_u) || !std::isfinite(h.origin_v) || !std::isfinite(h.cell_size) ||
      !(h.cell_size > 0))
    return bad("grid origin or cell size is not finite, or the cell size is not positive");
  if (!std::isfinite(h.eye_low) || !std::isfinite(h.eye_high) || h.eye_low > h.eye_high)
    return bad("eye heights are not finite or low > high");
  if (h.resolution_px < 1 || h.resolution_px > kMaxHintResolutionPx)
    return bad(
        fmt::format("face resolution {} px out of 1..{}", h.resolution_px, kMaxHintResolutionPx));
  if (h.positions_per_cell < 1 || h.positions_per_cell > 255 || h.directions < 1 ||
      h.directions > 255)
    return bad("positions per cell or directions out of 1..255");
  return {};
}

}  // namespace

uint64_t coverageHintsBytes(uint64_t cells, uint64_t entries) {
  return kCoverageHintsHeaderBytes + 4 * (cells + 1) + kCoverageHintEntryBytes * entries;
}

std::vector<uint8_t> encodeCoverageHints(const CoverageHints& h) {
  TESSERA_CHECK(checkGrid(h, "coverage hints").has_value()) << "invalid coverage hint grid";
  const uint32_t cells = h.cellCount();
  TESSERA_CHECK(h.cell_first.size() == cells + 1 && h.cell_first.back() == h.entries.size())
      << "coverage hints: cell table does not match the entries";
  std::vector<uint8_t> out(coverageHintsBytes(cells, h.entries.size()), 0);
  uint8_t* p = out.data();
  std::memcpy(p, kMagic, 4);
  storeU16(p + 4, kVersion);
  p[6] = uint8_t(h.up_axis);
  storeU32(p + 8, h.cells_u);
  storeU32(p + 12, h.cells_v);
  storeU32(p + 16, h.texture_count);
  storeU32(p + 20, uint32_t(h.entries.size()));
  storeF32(p + 24, h.origin_u);
  storeF32(p + 28, h.origin_v);
  storeF32(p + 32, h.cell_size);
  storeF32(p + 36, h.eye_low);
  storeF32(p + 40, h.eye_high);
  storeU16(p + 44, uint16_t(h.resolution_px));
  p[46] = uint8_t(h.positions_per_cell);
  p[47] = uint8_t(h.directions);
  p += kCoverageHintsHeaderBytes;
  for (uint32_t first : h.cell_first) {
    storeU32(p, first);
    p += 4;
  }
  for (const CoverageHint& e : h.entries) {
    TESSERA_CHECK(e.texture < h.texture_count && e.texture <= 0xFFFF && e.coverage_q >= 1)
        << "coverage hint entry out of range";
    storeU16(p, uint16_t(e.texture));
    storeU16(p + 2, e.coverage_q);
    p += kCoverageHintEntryBytes;
  }
  return out;
}

Result<CoverageHints> decodeCoverageHints(std::span<const uint8_t> bytes,
                                          uint32_t scene_texture_count, const std::string& name) {
  const std::string what = name + ": coverage hints";
  if (bytes.size() < kCoverageHintsHeaderBytes || std::memcmp(bytes.data(), kMagic, 4) != 0)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: block of {} bytes does not start with TCVH", what, bytes.size()));
  const uint8_t* p = bytes.data();
  if (loadU16(p + 4) != kVersion)
    return fail(ErrorCode::kUnsupported,
                fmt::format("{}: version {} (this reader knows 1)", what, loadU16(p + 4)));
  if (p[7] != 0 || !allZero(p + 48, 16))
    return fail(ErrorCode::kCorrupt, what + ": non-zero reserved bytes");
  CoverageHints h;
  h.up_axis = p[6];
  h.cells_u = loadU32(p + 8);
  h.cells_v = loadU32(p + 12);
  h.texture_count = loadU32(p + 16);
  const uint32_t entry_count = loadU32(p + 20);
  h.origin_u = loadF32(p + 24);
  h.origin_v = loadF32(p + 28);
  h.cell_size = loadF32(p + 32);
  h.eye_low = loadF32(p + 36);
  h.eye_high = loadF32(p + 40);
  h.resolution_px = loadU16(p + 44);
  h.positions_per_cell = p[46];
  h.directions = p[47];
  TESSERA_TRY(checkGrid(h, what));
  if (h.texture_count != scene_texture_count)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: written for {} textures, the scene has {}",
                                                 what, h.texture_count, scene_texture_count));
  const uint32_t cells = h.cellCount();
  if (bytes.size() != coverageHintsBytes(cells, entry_count))
    return fail(
        ErrorCode::kCorrupt,
        fmt::format("{}: {} bytes, expected {} for {} cells and {} entries", what, bytes.size(),
                    coverageHintsBytes(cells, entry_count), cells, entry_count));
  const uint8_t* table = p + kCoverageHintsHeaderBytes;
  h.cell_first.resize(cells + 1);
  for (uint32_t c = 0; c <= cells; ++c) {
    h.cell_first[c] = loadU32(table + 4 * c);
    const uint32_t previous = c == 0 ? 0 : h.cell_first[c - 1];
    if (h.cell_first[c] < previous || h.cell_first[c] > entry_count)
      return fail(ErrorCode::kCorrupt, fmt::format("{}: cell table entry {} ({}) out of order",
                                                   what, c, h.cell_first[c]));
  }
  if (h.cell_first[0] != 0 || h.cell_first[cells] != entry_count)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: cell table runs [{}, {}), expected [0, {})", what, h.cell_first[0],
                            h.cell_first[cells], entry_count));
  const uint8_t* e = table + 4 * (uint64_t(cells) + 1);
  h.entries.resize(entry_count);
  for (uint32_t c = 0; c < cells; ++c) {
    for (uint32_t k = h.cell_first[c]; k < h.cell_first[c + 1]; ++k) {
      CoverageHint& hint = h.entries[k];
      hint.texture = loadU16(e + 4 * uint64_t(k));
      hint.coverage_q = loadU16(e + 4 * uint64_t(k) + 2);
      if (hint.texture >= h.texture_count || hint.coverage_q == 0 ||
          (k > h.cell_first[c] && hint.texture <= h.entries[k - 1].texture))
        return fail(ErrorCode::kCorrupt,
                    fmt::format("{}: cell {} entry {} (texture {}, coverage {}) out of range or "
                                "order",
                                what, c, k - h.cell_first[c], hint.texture, hint.coverage_q));
    }
  }
  return h;
}

}  // namespace tessera::detail
