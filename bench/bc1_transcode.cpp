// The load-time JPEG -> BC1 transcode (issue 30, item 4; docs/codecs.md, "Fast bc1
// transcoder"): IMAGE cut into TILE_PX tiles, each JPEG q85 on its own, then on one thread
// tiles/s (thread CPU time) of the JPEG decode alone, of the decode plus Tessera's fast BC1
// encoder, and of the decode plus libsquish's range fit (bc1 effort 1), the fast encoder alone on
// the decoded tiles, the ratios to the decode alone, and the PSNR of each BC1 result against the
// decoded JPEG. Each figure is the best of PASSES passes over every tile, the three measured in
// turn within a pass so that they share the load.
//
//   tessera_bc1_transcode IMAGE.jpg [TILE_PX] [PASSES]   # defaults 256 and 5
#include <turbojpeg.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <iterator>
#include <vector>

#include "bc/bc.h"
#include "codecs/bc1_fast.h"
#include "codecs/encode.h"

using namespace tessera;
using namespace tessera::detail;

namespace {

// The thread's CPU time, not the wall clock: on a shared machine the wall clock counts the time
// other processes hold the core.
double seconds() {
  timespec now{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &now);
  return double(now.tv_sec) + 1e-9 * double(now.tv_nsec);
}

/// The whole tiles of TILE_PX in the image at `path`, RGB.
std::vector<Image> readTiles(const char* path, uint32_t tile_px) {
  std::ifstream file(path, std::ios::binary);
  const std::vector<unsigned char> jpeg((std::istreambuf_iterator<char>(file)), {});
  std::vector<Image> tiles;
  tjhandle handle = tjInitDecompress();
  int width = 0, height = 0, subsampling = 0, colourspace = 0;
  if (jpeg.empty() || tjDecompressHeader3(handle, jpeg.data(), jpeg.size(), &width, &height,
                                          &subsampling, &colourspace) != 0) {
    tjDestroy(handle);
    return tiles;
  }
  std::vector<uint8_t> rgb(size_t(width) * height * 3);
  const int status =
      tjDecompress2(handle, jpeg.data(), jpeg.size(), rgb.data(), width, 0, height, TJPF_RGB, 0);
  tjDestroy(handle);
  if (status != 0) return tiles;
  for (uint32_t y0 = 0; y0 + tile_px <= uint32_t(height); y0 += tile_px)
    for (uint32_t x0 = 0; x0 + tile_px <= uint32_t(width); x0 += tile_px) {
      Image tile(tile_px, tile_px, 3);
      for (uint32_t y = 0; y < tile_px; ++y)
        std::copy_n(rgb.data() + (size_t(y0 + y) * width + x0) * 3, size_t(tile_px) * 3,
                    tile.row(y));
      tiles.push_back(std::move(tile));
    }
  return tiles;
}

/// Squared error of `payload`'s BC1 blocks against `reference`, and its sample count.
struct ErrorSum {
  double squared = 0;
  double samples = 0;
  void add(const Image& reference, std::span<const uint8_t> payload) {
    Image decoded(reference.width_px, reference.height_px, reference.channels);
    if (!decodeTile(Codec::kBc1, payload, decoded)) std::exit(1);
    for (size_t i = 0; i < reference.texels.size(); ++i) {
      const double d = double(reference.texels[i]) - double(decoded.texels[i]);
      squared += d * d;
    }
    samples += double(reference.texels.size());
  }
  double psnr() const { return 10 * std::log10(255.0 * 255.0 * samples / squared); }
};

void die(const Error& error) {
  std::fprintf(stderr, "tessera_bc1_transcode: %s\n", error.message.c_str());
  std::exit(1);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: tessera_bc1_transcode IMAGE.jpg [TILE_PX] [PASSES]\n");
    return 2;
  }
  const uint32_t tile_px = argc > 2 ? uint32_t(std::atoi(argv[2])) : 256;
  const int passes = argc > 3 ? std::max(1, std::atoi(argv[3])) : 5;
  const std::vector<Image> tiles = tile_px > 0 ? readTiles(argv[1], tile_px) : std::vector<Image>{};
  if (tiles.empty()) {
    std::fprintf(stderr, "%s: not a readable JPEG of at least one %u px tile\n", argv[1], tile_px);
    return 1;
  }
  std::vector<std::vector<uint8_t>> jpegs;
  EncodeOptions jpeg_options;
  jpeg_options.quality = 85;
  for (const Image& tile : tiles) {
    auto jpeg = encodeTile(Codec::kJpeg, tile.view(), jpeg_options);
    if (!jpeg) die(jpeg.error());
    jpegs.push_back(std::move(*jpeg));
  }
  EncodeOptions squish_options;
  squish_options.effort = 1;
  CodecScratch scratch;
  Image decoded(tile_px, tile_px, 3);
  std::vector<uint8_t> payload(bcPayloadBytes(Codec::kBc1, tile_px, tile_px));
  std::vector<Image> decoded_tiles;
  for (const auto& jpeg : jpegs) {
    if (auto r = decodeTile(Codec::kJpeg, jpeg, decoded, nullptr, &scratch); !r) die(r.error());
    decoded_tiles.push_back(decoded);
  }
  double decode_s = 1e30, fast_s = 1e30, squish_s = 1e30, fast_alone_s = 1e30;
  for (int pass = 0; pass < passes; ++pass) {
    double start = seconds();
    for (const Image& tile : decoded_tiles)
      if (auto r = encodeBc1Fast(tile.view(), payload); !r) die(r.error());
    fast_alone_s = std::min(fast_alone_s, seconds() - start);
    start = seconds();
    for (const auto& jpeg : jpegs)
      if (auto r = decodeTile(Codec::kJpeg, jpeg, decoded, nullptr, &scratch); !r) die(r.error());
    decode_s = std::min(decode_s, seconds() - start);
    start = seconds();
    for (const auto& jpeg : jpegs) {
      if (auto r = decodeTile(Codec::kJpeg, jpeg, decoded, nullptr, &scratch); !r) die(r.error());
      if (auto r = encodeBc1Fast(decoded.view(), payload); !r) die(r.error());
    }
    fast_s = std::min(fast_s, seconds() - start);
    start = seconds();
    for (const auto& jpeg : jpegs) {
      if (auto r = decodeTile(Codec::kJpeg, jpeg, decoded, nullptr, &scratch); !r) die(r.error());
      if (auto r = encodeTile(Codec::kBc1, decoded.view(), squish_options); !r) die(r.error());
    }
    squish_s = std::min(squish_s, seconds() - start);
  }
  ErrorSum fast_error, squish_error;
  for (const auto& jpeg : jpegs) {
    if (auto r = decodeTile(Codec::kJpeg, jpeg, decoded, nullptr, &scratch); !r) die(r.error());
    if (auto r = encodeBc1Fast(decoded.view(), payload); !r) die(r.error());
    fast_error.add(decoded, payload);
    auto squished = encodeTile(Codec::kBc1, decoded.view(), squish_options);
    if (!squished) die(squished.error());
    squish_error.add(decoded, *squished);
  }
  const double count = double(jpegs.size());
  std::printf("%zu tiles of %u px from %s, JPEG q85, one thread, CPU time, best of %d passes\n",
              jpegs.size(), tile_px, argv[1], passes);
  std::printf("%-26s %10s %10s %14s %10s\n", "", "tiles/s", "ms/tile", "vs decode", "PSNR dB");
  std::printf("%-26s %10.0f %10.3f %13.2fx %10s\n", "jpeg decode", count / decode_s,
              1e3 * decode_s / count, 1.0, "-");
  std::printf("%-26s %10.0f %10.3f %13.2fx %10.2f\n", "decode + fast bc1", count / fast_s,
              1e3 * fast_s / count, fast_s / decode_s, fast_error.psnr());
  std::printf("%-26s %10.0f %10.3f %13.2fx %10s\n", "fast bc1 alone", count / fast_alone_s,
              1e3 * fast_alone_s / count, fast_alone_s / decode_s, "-");
  std::printf("%-26s %10.0f %10.3f %13.2fx %10.2f\n", "decode + squish range fit", count / squish_s,
              1e3 * squish_s / count, squish_s / decode_s, squish_error.psnr());
  return 0;
}
