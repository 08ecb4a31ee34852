// Fuzzes the builder's band readers over libtiff, libpng and libjpeg, and the mosaic manifest
// parser (src/builder): the input is written to a file, opened by content (openBandReader), and
// read top to bottom in bands.
// Checks that what opens describes a sane image and that a reader never writes outside the
// band it is given; the memory a reader takes is bounded by libFuzzer's RSS limit. Bands are
// read while the image is at most kMaxPixels, so a huge claimed size costs one open, not a
// long decode.
#include <unistd.h>

#include <cstdio>
#include <string>
#include <vector>

#include "builder/band_reader.h"
#include "format_fuzz_input.h"

namespace {

constexpr uint64_t kMaxPixels = 1u << 22;
constexpr uint8_t kCanary = 0xA5;

std::string inputPath() {
  static const std::string path =
      "/tmp/tessera_band_reader_fuzz_" + std::to_string(::getpid()) + ".img";
  return path;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace tessera;
  const std::string path = inputPath();
  std::FILE* file = std::fopen(path.c_str(), "wb");
  if (file == nullptr) fuzz::die("band_reader_fuzzer", "cannot write the input file");
  std::fwrite(data, 1, size, file);
  std::fclose(file);
  Result<std::unique_ptr<detail::BandReader>> reader = detail::openBandReader(path);
  if (!reader) return 0;
  const detail::SourceInfo& info = (*reader)->info();
  if (info.width_px == 0 || info.height_px == 0 || info.width_px > kMaxImageSidePx ||
      info.height_px > kMaxImageSidePx || info.channels < 1 || info.channels > 4 ||
      info.natural_band_rows == 0)
    fuzz::die("band_reader_fuzzer", "opened an image outside the reader's contract");
  if (uint64_t(info.width_px) * info.height_px > kMaxPixels) return 0;
  // 16-bit and float sources hand over their samples as they are: 2 or 4 bytes each.
  const size_t row_bytes = size_t(info.width_px) * info.channels * sampleBytes(info.sample_type);
  const uint32_t band = std::min<uint32_t>(info.natural_band_rows, 64);
  std::vector<uint8_t> out;
  for (uint32_t y = 0; y < info.height_px; y += band) {
    const uint32_t rows = std::min(band, info.height_px - y);
    out.assign(row_bytes * rows + 64, kCanary);
    if (!(*reader)->readRows(rows, std::span(out).first(row_bytes * rows))) return 0;
    for (size_t i = row_bytes * rows; i < out.size(); ++i)
      if (out[i] != kCanary) fuzz::die("band_reader_fuzzer", "a reader wrote past its band");
  }
  return 0;
}
