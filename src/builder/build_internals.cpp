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

/// coarsestLevelStatistics for u16 and f32 samples; NaN and infinities are left out (their
/// counts are given), so the figures stay numbers JSON can hold.
nlohmann::json wideLevelStatistics(const LevelRows& rows) {
  const uint32_t channels = rows.channels;
  std::vector<double> sum(channels, 0), low(channels, INFINITY), high(channels, -INFINITY);
  std::vector<uint64_t> finite(channels, 0), non_finite(channels, 0);
  const size_t sample_bytes = sampleBytes(rows.sample_type);
  for (uint32_t y = 0; y < rows.height_px; ++y) {
    const uint8_t* row = rows.row(y);
    for (size_t i = 0; i < size_t(rows.width_px) * channels; ++i) {
      double value;
      if (rows.sample_type == SampleType::kU16) {
        uint16_t sample;
        std::memcpy(&sample, row + i * sample_bytes, 2);
        value = sample;
      } else {
        float sample;
        std::memcpy(&sample, row + i * sample_bytes, 4);
        value = sample;
      }
      const uint32_t c = uint32_t(i % channels);
      if (!std::isfinite(value)) {
        ++non_finite[c];
        continue;
      }
      ++finite[c];
      sum[c] += value;
      low[c] = std::min(low[c], value);
      high[c] = std::max(high[c], value);
    }
  }
  nlohmann::json mean = nlohmann::json::array(), min = nlohmann::json::array(),
                 max = nlohmann::json::array();
  for (uint32_t c = 0; c < channels; ++c) {
    mean.push_back(finite[c] ? nlohmann::json(sum[c] / double(finite[c])) : nlohmann::json());
    min.push_back(finite[c] ? nlohmann::json(low[c]) : nlohmann::json());
    max.push_back(finite[c] ? nlohmann::json(high[c]) : nlohmann::json());
  }
  return {{"from_level_width", rows.width_px},
          {"mean", mean},
          {"min", min},
          {"max", max},
          {"non_finite", non_finite}};
}

std::string displayName(const std::string& input) {
  if (input.rfind("synthetic:", 0) == 0 || input.rfind("grid:", 0) == 0) return input;
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
  // Only wide images say so: 8-bit archives stay byte-identical to those of 1.0 writers.
  if (info.sample_type != SampleType::kU8) meta["sample_type"] = sampleTypeName(info.sample_type);
  for (auto& [key, value] : source.metadata.items()) meta[key] = value;
  return meta;
}

/// The archive's metadata: the format, the build's options and each image's entry.
nlohmann::json archiveMetadata(const BuildOptions& options, nlohmann::json image_metadata) {
  // The header's version (minorVersionFor): wide samples make the archive 1.2.
  uint16_t minor = kFormatVersionMinor;
  for (const nlohmann::json& image : image_metadata)
    if (image.value("sample_type", "u8") != "u8") minor = kSampleTypeMinorVersion;
  return {{"format", "tessera"},
          {"format_version", fmt::format("{}.{}", kFormatVersionMajor, minor)},
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
