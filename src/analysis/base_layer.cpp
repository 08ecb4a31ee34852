#include "base_layer.h"

#include <unistd.h>

#include <filesystem>

#include <fmt/format.h>

#include <tessera/archive.h>
#include <tessera/build.h>
#include <tessera/procedural_build.h>

namespace tessera::detail {

namespace {

constexpr uint32_t kMaxLayerSide = 4096;

/// A picture as a temporary zstd archive, removed with this object.
struct TemporaryArchive {
  std::string path;
  std::shared_ptr<Archive> archive;
  ~TemporaryArchive() {
    archive.reset();
    std::error_code ec;
    if (!path.empty()) std::filesystem::remove(path, ec);
  }
};

Result<void> openAsArchive(const std::string& path, const std::string& scratch_dir,
                           TemporaryArchive& temporary) {
  temporary.path =
      (std::filesystem::path(scratch_dir.empty() ? "." : scratch_dir) /
       fmt::format(".tessera-picture-{}-{}.tess", ::getpid(), std::hash<std::string>{}(path)))
          .string();
  BuildOptions options;
  options.inputs = {path};
  options.output = temporary.path;
  options.codec = Codec::kZstd;
  options.threads = 1;
  Result<BuildReport> built = buildArchive(options);
  if (!built) {
    temporary.path.clear();
    return fail(built.error().code, built.error().message);
  }
  TESSERA_ASSIGN_OR_RETURN(temporary.archive, Archive::openFile(temporary.path));
  return {};
}

}  // namespace

Result<BaseLayer> loadBaseLayer(const std::string& path, const std::string& scratch_dir) {
  TemporaryArchive temporary;
  Result<void> opened = openAsArchive(path, scratch_dir, temporary);
  if (!opened) return fail(opened.error().code, "base layer: " + opened.error().message);
  const std::shared_ptr<Archive>& archive = temporary.archive;
  const ImageInfo& info = archive->images()[0];
  uint32_t level = 0;
  while (level + 1 < info.level_count &&
         std::max(info.levelWidthPx(level), info.levelHeightPx(level)) > kMaxLayerSide)
    ++level;
  const uint32_t w = info.levelWidthPx(level), h = info.levelHeightPx(level);
  TESSERA_ASSIGN_OR_RETURN(Image region, archive->readRegion(0, level, {0, 0, w, h}));
  BaseLayer layer;
  layer.source_width_px = info.width_px;
  layer.source_height_px = info.height_px;
  layer.height = Image(w, h, 1);
  for (size_t i = 0; i < size_t(w) * h; ++i)
    layer.height.texels[i] = region.texels[i * region.channels];
  return layer;
}

}  // namespace tessera::detail

namespace tessera {

Result<Image> readImageRgba(const std::string& path, const std::string& scratch_dir) {
  detail::TemporaryArchive temporary;
  TESSERA_TRY(detail::openAsArchive(path, scratch_dir, temporary));
  const ImageInfo& info = temporary.archive->images()[0];
  if (info.width_px > kMaxBrushSidePx || info.height_px > kMaxBrushSidePx)
    return fail(ErrorCode::kTooLarge,
                fmt::format("{}: {}x{} is larger than a brush may be ({} a "
                            "side)",
                            path, info.width_px, info.height_px, kMaxBrushSidePx));
  return temporary.archive->readRegionRgba(0, 0, {0, 0, info.width_px, info.height_px});
}

}  // namespace tessera
