#include "base_layer.h"

#include <unistd.h>

#include <filesystem>

#include <fmt/format.h>

#include <tessera/archive.h>
#include <tessera/build.h>

namespace tessera::detail {

namespace {

constexpr uint32_t kMaxLayerSide = 4096;

}  // namespace

Result<BaseLayer> loadBaseLayer(const std::string& path, const std::string& scratch_dir) {
  const std::string temporary =
      (std::filesystem::path(scratch_dir.empty() ? "." : scratch_dir) /
       fmt::format(".tessera-base-{}-{}.tess", ::getpid(), std::hash<std::string>{}(path)))
          .string();
  BuildOptions options;
  options.inputs = {path};
  options.output = temporary;
  options.codec = Codec::kZstd;
  options.threads = 1;
  Result<BuildReport> built = buildArchive(options);
  if (!built) return fail(built.error().code, "base layer: " + built.error().message);
  struct Remove {
    std::string path;
    ~Remove() {
      std::error_code ec;
      std::filesystem::remove(path, ec);
    }
  } remove{temporary};
  TESSERA_ASSIGN_OR_RETURN(std::shared_ptr<Archive> archive, Archive::openFile(temporary));
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
