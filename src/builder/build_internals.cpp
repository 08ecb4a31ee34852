#include "build_internals.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>

#include <fmt/format.h>

#include "format/header.h"

namespace tessera::detail {

TileClass classifyTile(const uint8_t* texels, uint32_t side, uint32_t channels,
                       uint32_t* uniform_rgba) {
  const size_t row_bytes = size_t(side) * channels;
  uint8_t pattern[64 * 4];
  const uint32_t pattern_texels = 64;
  for (uint32_t i = 0; i < pattern_texels; ++i)
    std::memcpy(pattern + i * channels, texels, channels);
  const size_t total = row_bytes * side;
  const size_t pattern_bytes = size_t(pattern_texels) * channels;
  for (size_t pos = 0; pos < total; pos += pattern_bytes) {
    size_t n = std::min(pattern_bytes, total - pos);
    if (std::memcmp(texels + pos, pattern, n) != 0) return TileClass::kMixed;
  }
  uint32_t colour = 0;
  for (uint32_t c = 0; c < channels; ++c) colour |= uint32_t(texels[c]) << (8 * c);
  *uniform_rgba = colour;
  bool has_alpha = channels == 2 || channels == 4;
  return has_alpha && colour == 0 ? TileClass::kEmpty : TileClass::kUniform;
}

/// Summary statistics of an image, from its coarsest level (one tile: cheap, and the mean is
/// exact up to rounding of the box filter).
nlohmann::json coarsestLevelStatistics(const LevelRows& rows) {
  std::vector<uint64_t> sum(rows.channels, 0);
  std::vector<int> low(rows.channels, 255), high(rows.channels, 0);
  for (uint32_t y = 0; y < rows.height_px; ++y) {
    const uint8_t* row = rows.row(y);
    for (uint32_t x = 0; x < rows.width_px; ++x) {
      for (uint32_t c = 0; c < rows.channels; ++c) {
        int v = row[x * rows.channels + c];
        sum[c] += v;
        low[c] = std::min(low[c], v);
        high[c] = std::max(high[c], v);
      }
    }
  }
  nlohmann::json mean = nlohmann::json::array();
  double count = double(rows.width_px) * rows.height_px;
  for (uint64_t s : sum) mean.push_back(std::round(s / count * 100) / 100);
  return {{"from_level_width", rows.width_px}, {"mean", mean}, {"min", low}, {"max", high}};
}

std::string displayName(const std::string& input) {
  if (input.rfind("synthetic:", 0) == 0) return input;
  return std::filesystem::path(input).filename().string();
}

/// An image's entry in the archive metadata: its source and statistics, then the reader's
/// source-specific facts (georeference, TIFF layout, synthetic seed).
nlohmann::json imageMetadata(const ImageInfo& info, const std::string& input,
                             const SourceInfo& source, const nlohmann::json& statistics) {
  nlohmann::json meta = {
      {"name", info.name},       {"source", input},          {"source_format", source.format},
      {"width", info.width_px},  {"height", info.height_px}, {"channels", info.channels},
      {"statistics", statistics}};
  for (auto& [key, value] : source.metadata.items()) meta[key] = value;
  return meta;
}

/// The archive's metadata: the format, the build's options and each image's entry.
nlohmann::json archiveMetadata(const BuildOptions& options, nlohmann::json image_metadata) {
  return {{"format", "tessera"},
          {"format_version", fmt::format("{}.{}", kFormatVersionMajor, kFormatVersionMinor)},
          {"created_by", "tessera build"},
          {"build",
           {{"tile_size", options.tile_size_px},
            {"border", options.border_px},
            {"codec", codecName(options.codec)},
            {"quality", options.quality},
            {"effort", options.effort},
            {"chroma_subsampling", options.chroma_subsampling ? "4:2:0" : "4:4:4"},
            {"downsample", options.codec == Codec::kPtm ? "box-floor"
                           : options.srgb_downsample    ? "box-linear-light"
                                                        : "box"},
            {"order", options.order == TileOrder::kHilbert    ? "hilbert"
                      : options.order == TileOrder::kQuadtree ? "quadtree"
                                                              : "row-major"}}},
          {"images", std::move(image_metadata)}};
}

}  // namespace tessera::detail
