#pragma once
// A small archive of u16 or f32 samples computed per texel, for the display window's tests
// (renderers, server, reader). Header-only: every user links the builder already.
#include <cstring>
#include <functional>
#include <memory>
#include <string>

#include <gtest/gtest.h>

#include <tessera/archive.h>
#include <tessera/build.h>

namespace tessera::test {

/// Sample c of texel (x, y), converted to the archive's type as it is stored (u16 truncated).
using SampleFunction = std::function<double(uint32_t x, uint32_t y, uint32_t c)>;

/// Builds `path` (`codec`, `tile_size_px` tiles, `border_px`) from `sample` and opens it; fails
/// the test and returns null on error.
inline std::shared_ptr<Archive> buildWideArchive(const std::string& path, uint32_t width_px,
                                                 uint32_t height_px, uint32_t channels,
                                                 SampleType type, const SampleFunction& sample,
                                                 uint32_t tile_size_px = 64,
                                                 Codec codec = Codec::kZstd,
                                                 uint32_t border_px = 0) {
  RowSource source;
  source.name = "wide";
  source.width_px = width_px;
  source.height_px = height_px;
  source.channels = channels;
  source.sample_type = type;
  source.read_rows = [&](uint32_t first, uint32_t rows, std::span<uint8_t> out) {
    size_t i = 0;
    for (uint32_t y = first; y < first + rows; ++y)
      for (uint32_t x = 0; x < width_px; ++x)
        for (uint32_t c = 0; c < channels; ++c, ++i) {
          const double v = sample(x, y, c);
          if (type == SampleType::kU16) {
            const uint16_t s = uint16_t(v);
            std::memcpy(out.data() + i * 2, &s, 2);
          } else {
            const float s = float(v);
            std::memcpy(out.data() + i * 4, &s, 4);
          }
        }
    return Result<void>{};
  };
  BuildOptions options;
  options.row_sources = {source};
  options.output = path;
  options.tile_size_px = tile_size_px;
  options.codec = codec;
  options.border_px = border_px;
  auto report = buildArchive(options);
  EXPECT_TRUE(report) << report.error().message;
  if (!report) return nullptr;
  auto archive = Archive::openFile(path);
  EXPECT_TRUE(archive) << archive.error().message;
  return archive ? *archive : nullptr;
}

}  // namespace tessera::test
