#pragma once
// The coverage hints section of a version 1.1 scene archive (docs/format.md, "Coverage
// hints"): Marvie & Bouatouch's average coverage hints (seed 003 part II) per view cell of a
// regular grid, one block, the section of kind kCoverageHints. Pure: bytes in, structs out.

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <tessera/coverage_hints.h>
#include <tessera/result.h>

namespace tessera::detail {

inline constexpr uint32_t kCoverageHintsHeaderBytes = 64;
inline constexpr uint32_t kCoverageHintEntryBytes = 4;
/// Bounds that keep a hostile block from driving allocations.
inline constexpr uint32_t kMaxHintCellsPerAxis = 4096;
inline constexpr uint32_t kMaxHintCells = 1u << 20;
inline constexpr uint32_t kMaxHintResolutionPx = 4096;
inline constexpr uint64_t kMaxCoverageHintsBytes = 64ull << 20;

/// Bytes of the block for the given cells and entries.
uint64_t coverageHintsBytes(uint64_t cells, uint64_t entries);

/// The block's bytes. The hints must be valid (checked).
std::vector<uint8_t> encodeCoverageHints(const CoverageHints& hints);

/// Decodes a block already checked against its BlockRef's checksum: magic and version, the
/// grid (cells per axis 1..4096, at most 2^20 cells, finite origin, cell size > 0, finite
/// eye heights low <= high, resolution 1..4096, up axis 0..2), texture_count equal to the
/// scene's, the length exactly 64 + 4 (cells + 1) + 4 entries, the cell table starting at 0,
/// non-decreasing and ending at the entry count, and within each cell textures strictly
/// increasing, below texture_count, coverage >= 1. Errors name `name` and the field (kCorrupt;
/// a newer version: kUnsupported).
Result<CoverageHints> decodeCoverageHints(std::span<const uint8_t> bytes,
                                          uint32_t scene_texture_count, const std::string& name);

}  // namespace tessera::detail
