// Builds a small synthetic archive and reads it back through the installed public API only.
// Usage: consumer WORK_DIR. Exits 0 when every check passes, 1 with a message otherwise.

#include <cstdio>
#include <string>

#include <tessera/archive.h>
#include <tessera/build.h>
#include <tessera/format.h>
#include <tessera/result.h>

namespace {

int failWith(const std::string& message) {
  std::fprintf(stderr, "consumer: %s\n", message.c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) return failWith("usage: consumer WORK_DIR");

  tessera::BuildOptions options;
  options.inputs = {"synthetic:600x400:7"};
  options.output = std::string(argv[1]) + "/consumer.tess";
  options.tile_size_px = 128;
  options.border_px = 1;
  options.codec = tessera::Codec::kPng;
  options.threads = 2;
  tessera::Result<tessera::BuildReport> report = tessera::buildArchive(options);
  if (!report) return failWith("build failed: " + report.error().message);

  auto archive = tessera::Archive::openFile(options.output);
  if (!archive) return failWith("open failed: " + archive.error().message);
  const auto& images = (*archive)->images();
  if (images.size() != 1) return failWith("expected 1 image, got " + std::to_string(images.size()));
  const tessera::ImageInfo& info = images[0];
  if (info.width_px != 600 || info.height_px != 400) {
    return failWith("expected 600x400, got " + std::to_string(info.width_px) + "x" +
                    std::to_string(info.height_px));
  }
  if (info.level_count != tessera::levelCountFor(600, 400, 128)) {
    return failWith("unexpected level count " + std::to_string(info.level_count));
  }
  if ((*archive)->fileBytes() != report->output_bytes) {
    return failWith("file size in header differs from the build report");
  }

  // Every level must read back as a whole RGBA rectangle.
  for (uint32_t level = 0; level < info.level_count; ++level) {
    tessera::PixelRect rect{0, 0, info.levelWidthPx(level), info.levelHeightPx(level)};
    auto region = (*archive)->readRegionRgba(0, level, rect);
    if (!region) return failWith("level " + std::to_string(level) + ": " + region.error().message);
    if (region->width_px != rect.width || region->height_px != rect.height ||
        region->channels != 4) {
      return failWith("level " + std::to_string(level) + ": wrong region geometry");
    }
  }
  auto tile = (*archive)->readTile(tessera::TileId{0, 0, 0, 0});
  if (!tile) return failWith("tile (0,0,0): " + tile.error().message);
  if (tile->width_px != info.storedTileSidePx()) return failWith("tile has the wrong side");

  std::printf("consumer: ok, %ux%u, %u levels, %llu bytes\n", info.width_px, info.height_px,
              info.level_count, static_cast<unsigned long long>((*archive)->fileBytes()));
  return 0;
}
