// Which input is a pyramid, and which archive levels an import copies or computes.

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <string_view>

#include <fmt/format.h>

#include "file_reader.h"
#include "pyramid_source.h"

namespace tessera::detail {
namespace {

constexpr std::string_view kOpenSlidePrefix = "openslide:";

bool hasTiffMagic(const std::string& path) {
  // Not a regular file (a FIFO would block the open): not a pyramid; the band readers refuse it.
  if (!checkSourceFile(path)) return false;
  std::FILE* file = std::fopen(path.c_str(), "rb");
  if (!file) return false;
  std::array<unsigned char, 4> magic{};
  const size_t got = std::fread(magic.data(), 1, magic.size(), file);
  std::fclose(file);
  if (got < 4) return false;
  return (magic[0] == 'I' && magic[1] == 'I' && (magic[2] == 42 || magic[2] == 43)) ||
         (magic[0] == 'M' && magic[1] == 'M' && (magic[3] == 42 || magic[3] == 43));
}

std::string lowerExtension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  return ext;
}

}  // namespace

Result<std::unique_ptr<PyramidSource>> openPyramidSource(const std::string& path) {
  if (path.starts_with(kOpenSlidePrefix)) return openSlide(path.substr(kOpenSlidePrefix.size()));
  const std::string ext = lowerExtension(path);
  if (ext == ".dzi") return openDeepZoom(path);
  // Slide formats that are not TIFF-based, or whose TIFF layout only OpenSlide understands.
  for (std::string_view slide :
       {".svs", ".ndpi", ".vms", ".vmu", ".scn", ".mrxs", ".bif", ".svslide"}) {
    if (ext == slide) return openSlide(path);
  }
  if (hasTiffMagic(path)) return openTiffPyramid(path);
  return std::unique_ptr<PyramidSource>();
}

ImportPlan planImport(const ImageInfo& info, const std::vector<SourceLevel>& levels,
                      bool reuse_levels) {
  ImportPlan plan;
  plan.copied_from.assign(info.level_count, -1);
  if (!reuse_levels) {
    plan.passes.push_back({0, 0, info.level_count - 1});
    return plan;
  }
  std::vector<int> matched(info.level_count, -1);
  for (uint32_t l = 0; l < info.level_count; ++l) {
    for (size_t s = 0; s < levels.size(); ++s) {
      if (levels[s].width_px == info.levelWidthPx(l) &&
          levels[s].height_px == info.levelHeightPx(l)) {
        matched[l] = int(s);
        break;
      }
    }
  }
  matched[0] = 0;
  auto copyable = [&](const SourceLevel& level) {
    if (info.border_px != 0 || level.tile_size_px != info.tile_size_px) return false;
    if (info.default_codec == Codec::kJpeg) return level.jpeg_tiles;
    return info.default_codec == Codec::kZstd && info.sample_type != SampleType::kU8 &&
           level.zstd_tiles && level.zstd_sample_type == info.sample_type &&
           level.zstd_channels == info.channels;
  };
  for (uint32_t l = 0; l + 1 < info.level_count; ++l) {
    const int s = matched[l];
    if (s >= 0 && copyable(levels[s])) plan.copied_from[l] = s;
  }
  // Each computed level joins the pass of the nearest finer matching level.
  for (uint32_t l = 0; l < info.level_count; ++l) {
    if (plan.copied_from[l] >= 0) continue;
    uint32_t base = l;
    while (matched[base] < 0) --base;
    if (!plan.passes.empty() && plan.passes.back().first_level == base) {
      plan.passes.back().last_level = l;
    } else {
      plan.passes.push_back({uint32_t(matched[base]), base, l});
    }
  }
  return plan;
}

}  // namespace tessera::detail

namespace tessera::detail {

Result<void> checkJpegTile(std::span<const uint8_t> jpeg, uint32_t side_px, uint32_t channels,
                           const std::string& what) {
  auto bad = [&](const std::string& why) {
    return fail(ErrorCode::kCorrupt, fmt::format("{}: stored JPEG {}", what, why));
  };
  if (jpeg.size() < 4 || jpeg[0] != 0xFF || jpeg[1] != 0xD8) return bad("does not start with SOI");
  size_t pos = 2;
  while (pos + 4 <= jpeg.size()) {
    if (jpeg[pos] != 0xFF) return bad(fmt::format("has no marker at byte {}", pos));
    const uint8_t marker = jpeg[pos + 1];
    if (marker == 0xFF) {
      ++pos;  // fill byte
      continue;
    }
    const size_t length = size_t(jpeg[pos + 2]) << 8 | jpeg[pos + 3];
    if (length < 2 || pos + 2 + length > jpeg.size()) return bad("has a segment past its end");
    if (marker >= 0xC0 && marker <= 0xC2) {
      if (length < 8) return bad("has a short frame header");
      const uint32_t height = uint32_t(jpeg[pos + 5]) << 8 | jpeg[pos + 6];
      const uint32_t width = uint32_t(jpeg[pos + 7]) << 8 | jpeg[pos + 8];
      const uint32_t components = jpeg[pos + 9];
      if (width != side_px || height != side_px || components != channels)
        return bad(fmt::format("is {}x{} px with {} component(s), not {}x{} with {}", width, height,
                               components, side_px, side_px, channels));
      return {};
    }
    if (marker == 0xDA ||
        (marker >= 0xC3 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC))
      return bad("is not baseline or progressive Huffman-coded");
    pos += 2 + length;
  }
  return bad("has no frame header");
}

}  // namespace tessera::detail
