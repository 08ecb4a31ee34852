// bc1 and bc7 on real imagery: PSNR against the source, encode speed per effort, JPEG decode
// plus a BC1 transcode against JPEG decode alone, and bytes per tile (docs/codecs.md,
// "bc1 (8) and bc7 (9)"). Usage: tessera_bc_bench IMAGE.jpg [TILE_PX]; IMAGE is cut into
// TILE_PX tiles (default 256), each coded on its own.
#include <turbojpeg.h>
#include <zstd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <vector>

#include "bc/bc.h"
#include "codecs/encode.h"

using namespace tessera;
using namespace tessera::detail;

namespace {

double seconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

std::vector<Image> cutTiles(const char* path, uint32_t tile_px) {
  std::ifstream file(path, std::ios::binary);
  std::vector<unsigned char> jpeg((std::istreambuf_iterator<char>(file)), {});
  tjhandle handle = tjInitDecompress();
  int width = 0, height = 0, subsampling = 0, colourspace = 0;
  std::vector<Image> tiles;
  if (tjDecompressHeader3(handle, jpeg.data(), jpeg.size(), &width, &height, &subsampling,
                          &colourspace) != 0)
    return tiles;
  std::vector<uint8_t> rgb(size_t(width) * height * 3);
  tjDecompress2(handle, jpeg.data(), jpeg.size(), rgb.data(), width, 0, height, TJPF_RGB, 0);
  tjDestroy(handle);
  for (uint32_t ty = 0; ty + tile_px <= uint32_t(height); ty += tile_px)
    for (uint32_t tx = 0; tx + tile_px <= uint32_t(width); tx += tile_px) {
      Image tile(tile_px, tile_px, 3);
      for (uint32_t y = 0; y < tile_px; ++y)
        std::copy_n(rgb.data() + (size_t(ty + y) * width + tx) * 3, tile_px * 3, tile.row(y));
      tiles.push_back(std::move(tile));
    }
  return tiles;
}

struct Totals {
  double squared_error = 0;
  double samples = 0;
  double encode_s = 0;
  double payload_bytes = 0;
  double zstd_bytes = 0;
  double psnr() const { return 10 * std::log10(255.0 * 255.0 * samples / squared_error); }
};

Totals measure(Codec codec, int effort, int quality, const std::vector<Image>& tiles) {
  Totals totals;
  EncodeOptions options;
  options.effort = effort;
  options.quality = quality;
  for (const Image& tile : tiles) {
    const double start = seconds();
    auto payload = encodeTile(codec, tile.view(), options);
    totals.encode_s += seconds() - start;
    if (!payload) {
      std::fprintf(stderr, "%s\n", payload.error().message.c_str());
      std::exit(1);
    }
    Image decoded(tile.width_px, tile.height_px, 3);
    if (!decodeTile(codec, *payload, decoded)) std::exit(1);
    for (size_t i = 0; i < tile.texels.size(); ++i) {
      const double d = double(tile.texels[i]) - double(decoded.texels[i]);
      totals.squared_error += d * d;
    }
    totals.samples += double(tile.texels.size());
    totals.payload_bytes += double(payload->size());
    std::vector<uint8_t> frame(ZSTD_compressBound(payload->size()));
    totals.zstd_bytes +=
        double(ZSTD_compress(frame.data(), frame.size(), payload->data(), payload->size(), 3));
  }
  return totals;
}

/// JPEG decode alone, and JPEG decode followed by a BC1 encode of the decoded tile (the load-
/// time transcode), best of three passes over every tile.
void measureTranscode(const std::vector<Image>& tiles, int bc1_effort) {
  std::vector<std::vector<uint8_t>> jpegs;
  for (const Image& tile : tiles) jpegs.push_back(*encodeTile(Codec::kJpeg, tile.view(), {}));
  CodecScratch scratch;
  double decode_best = 1e9, transcode_best = 1e9;
  EncodeOptions options;
  options.effort = bc1_effort;
  for (int pass = 0; pass < 3; ++pass) {
    double decode = 0, transcode = 0;
    for (const auto& jpeg : jpegs) {
      Image decoded(tiles[0].width_px, tiles[0].height_px, 3);
      const double start = seconds();
      if (!decodeTile(Codec::kJpeg, jpeg, decoded, nullptr, &scratch)) std::exit(1);
      const double middle = seconds();
      if (!encodeTile(Codec::kBc1, decoded.view(), options)) std::exit(1);
      decode += middle - start;
      transcode += seconds() - start;
    }
    decode_best = std::min(decode_best, decode),
    transcode_best = std::min(transcode_best, transcode);
  }
  std::printf(
      "transcode bc1 effort %d: jpeg decode %.2f ms/tile, decode + bc1 %.2f ms/tile, "
      "ratio %.2f\n",
      bc1_effort, 1e3 * decode_best / jpegs.size(), 1e3 * transcode_best / jpegs.size(),
      transcode_best / decode_best);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: tessera_bc_bench IMAGE.jpg [TILE_PX]\n");
    return 2;
  }
  const uint32_t tile_px = argc > 2 ? uint32_t(std::atoi(argv[2])) : 256;
  const std::vector<Image> tiles = cutTiles(argv[1], tile_px);
  if (tiles.empty()) {
    std::fprintf(stderr, "%s: not a readable JPEG of at least one %u px tile\n", argv[1], tile_px);
    return 1;
  }
  const double rgba_bytes = double(tile_px) * tile_px * 4;
  std::printf("%zu tiles of %u px from %s; RGBA8 %.0f bytes per tile\n", tiles.size(), tile_px,
              argv[1], rgba_bytes);
  std::printf("%-6s %6s %8s %12s %12s %10s %10s\n", "codec", "effort", "PSNR dB", "Mpx/s encode",
              "bytes/tile", "vs RGBA8", "zstd/raw");
  struct Row {
    Codec codec;
    int effort;
  };
  for (Row row :
       {Row{Codec::kBc1, 1}, Row{Codec::kBc1, 2}, Row{Codec::kBc1, 3}, Row{Codec::kBc7, 1},
        Row{Codec::kBc7, 2}, Row{Codec::kBc7, 4}, Row{Codec::kJpeg, 0}}) {
    const Totals t = measure(row.codec, row.effort, 85, tiles);
    const double pixels = double(tiles.size()) * tile_px * tile_px;
    std::printf("%-6s %6d %8.2f %12.2f %12.0f %9.1fx %10.3f\n", codecName(row.codec), row.effort,
                t.psnr(), pixels / t.encode_s / 1e6, t.payload_bytes / tiles.size(),
                rgba_bytes * tiles.size() / t.payload_bytes, t.zstd_bytes / t.payload_bytes);
  }
  measureTranscode(tiles, 1);
  measureTranscode(tiles, 2);
  return 0;
}
