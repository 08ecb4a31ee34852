#pragma once
// Pieces of buildArchive that split builds (part_build.cpp) and their merge (merge.cpp) share
// with it, so that a merged archive's tiles and metadata are those of a single build.

#include <cstdint>
#include <string>

#include <nlohmann/json.hpp>

#include <tessera/build.h>
#include <tessera/format.h>

#include "band_reader.h"
#include "tile_cutter.h"

namespace tessera::detail {

enum class TileClass { kEmpty, kUniform, kMixed };

/// Empty means every byte is zero in an image with alpha: nothing to draw. Uniform means every
/// texel, border and padding included, equals the first; `uniform_rgba` receives it.
TileClass classifyTile(const uint8_t* texels, uint32_t side, uint32_t channels,
                       uint32_t* uniform_rgba);

/// Summary statistics of an image, from its coarsest level.
nlohmann::json coarsestLevelStatistics(const LevelRows& rows);
/// coarsestLevelStatistics for u16 and f32 samples; NaN and infinities are left out (their
/// counts are given), so the figures stay numbers JSON can hold.
nlohmann::json wideLevelStatistics(const LevelRows& rows);

/// The name an input gets when none is given: its file name, or the synthetic spec.
std::string displayName(const std::string& input);

/// An image's entry in the archive metadata: its source and statistics, then the reader's
/// source-specific facts (georeference, TIFF layout, synthetic seed).
nlohmann::json imageMetadata(const ImageInfo& info, const std::string& input,
                             const SourceInfo& source, const nlohmann::json& statistics);

/// The archive's metadata: the format, the build's options and each image's entry.
nlohmann::json archiveMetadata(const BuildOptions& options, nlohmann::json image_metadata);

}  // namespace tessera::detail
