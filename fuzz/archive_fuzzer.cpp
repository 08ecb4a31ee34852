// Fuzzes the whole reader: an archive file, opened from memory, every directory entry read
// and every tile decoded (at most kMaxTiles, so a hostile geometry cannot make a run slow),
// then verify. Checks that nothing crashes, hangs or reads out of range, and that a tile that
// reads back does so in its stored geometry.
#include <tessera/archive.h>

#include "format_fuzz_input.h"

namespace {

constexpr uint32_t kMaxTiles = 256;

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace tessera;
  Result<std::shared_ptr<Archive>> opened =
      Archive::open(makeMemorySource(std::vector<uint8_t>(data, data + size), "fuzz.tess"));
  if (!opened) return 0;
  const Archive& archive = **opened;
  CodecScratch scratch;
  uint32_t tiles = 0;
  for (uint32_t image = 0; image < archive.images().size(); ++image) {
    const ImageInfo& info = archive.images()[image];
    for (uint32_t level = info.level_count; level-- > 0;)
      for (uint32_t y = 0; y < info.tilesY(level); ++y)
        for (uint32_t x = 0; x < info.tilesX(level); ++x) {
          if (++tiles > kMaxTiles) return 0;
          Result<Image> tile = archive.readTile({image, level, x, y}, &scratch);
          if (tile &&
              (tile->width_px != info.storedTileSidePx() ||
               tile->height_px != info.storedTileSidePx() || tile->channels != info.channels))
            fuzz::die("archive_fuzzer", "a tile read back in the wrong geometry");
        }
  }
  const VerifyReport report = archive.verify();
  if (!report.ok() && report.faults.empty()) fuzz::die("archive_fuzzer", "faults without text");
  return 0;
}
