// Tile codec throughput on one core. JPEG is reported in tiles/s (items_per_second) for the
// builder's common tile shapes, 256x256 and 258x258 (256 + a 1-px border), RGB at quality 85
// with 4:2:0, the libvips defaults we compare against; every codec is also reported in MB/s of
// raw texels (bytes_per_second) with its compression ratio, at its default and a few efforts.
//
//   ninja -C build-bench tessera_codec_bench && build-bench/bench/tessera_codec_bench
#include <cmath>
#include <cstdint>
#include <vector>

#include <benchmark/benchmark.h>

#include "codecs/encode.h"

namespace {

using tessera::Codec;
using tessera::CodecScratch;
using tessera::Image;
using tessera::detail::EncodeOptions;

uint32_t hash(uint32_t x, uint32_t y, uint32_t seed) {
  uint32_t h = x * 374761393u + y * 668265263u + seed * 2246822519u;
  h = (h ^ (h >> 13)) * 1274126177u;
  return h ^ (h >> 16);
}

// Fractal value noise (5 octaves, gain 0.5) per channel plus +-2 codes of sensor noise: the
// spectrum of aerial and terrain imagery, which is what Tessera tiles mostly hold. Flat or
// purely random tiles would flatter or punish the entropy coders. The sensor noise is why the
// byte-oriented LZ coders barely compress it, as on real photographs.
Image makeImageLike(uint32_t width, uint32_t height, uint32_t channels) {
  Image image(width, height, channels);
  for (uint32_t y = 0; y < height; ++y) {
    for (uint32_t x = 0; x < width; ++x) {
      for (uint32_t c = 0; c < channels; ++c) {
        double value = 0, amplitude = 64, cell = 64;
        for (int octave = 0; octave < 5; ++octave, amplitude *= 0.5, cell *= 0.5) {
          const double fx = x / cell, fy = y / cell;
          const uint32_t ix = uint32_t(fx), iy = uint32_t(fy);
          double tx = fx - ix, ty = fy - iy;
          tx = tx * tx * (3 - 2 * tx);
          ty = ty * ty * (3 - 2 * ty);
          auto lattice = [&](uint32_t lx, uint32_t ly) {
            return (hash(lx, ly, c * 8 + octave) & 0xFFFF) / 65535.0 - 0.5;
          };
          const double top = lattice(ix, iy) * (1 - tx) + lattice(ix + 1, iy) * tx;
          const double bottom = lattice(ix, iy + 1) * (1 - tx) + lattice(ix + 1, iy + 1) * tx;
          value += amplitude * 2 * (top * (1 - ty) + bottom * ty);
        }
        value += 128 + double(int(hash(x, y, 99 + c) % 5) - 2);
        if (c == 3) {
          // Alpha is a mask, not a texture: opaque with a soft-edged transparent disk, as
          // around the footprint of a scanned map or an image's padded edge.
          const double dx = x - width * 0.7, dy = y - height * 0.3;
          value = (std::sqrt(dx * dx + dy * dy) - width * 0.2) * 64;
        }
        image.row(y)[size_t(x) * channels + c] = uint8_t(std::fmin(255.0, std::fmax(0.0, value)));
      }
    }
  }
  return image;
}

// Args: codec, tile side, channels, effort (0 = default), quality.
void setLabel(benchmark::State& state, size_t raw_bytes, size_t payload_bytes) {
  state.SetBytesProcessed(int64_t(state.iterations()) * int64_t(raw_bytes));
  state.SetItemsProcessed(int64_t(state.iterations()));
  state.counters["ratio"] = double(raw_bytes) / double(payload_bytes);
  state.counters["payload_bytes"] = double(payload_bytes);
}

EncodeOptions optionsFrom(const benchmark::State& state) {
  EncodeOptions options;
  options.effort = int(state.range(3));
  options.quality = int(state.range(4));
  return options;
}

void BM_Encode(benchmark::State& state) {
  const Codec codec = Codec(state.range(0));
  const uint32_t side = uint32_t(state.range(1)), channels = uint32_t(state.range(2));
  const Image tile = makeImageLike(side, side, channels);
  const EncodeOptions options = optionsFrom(state);
  CodecScratch scratch;
  size_t payload_bytes = 0;
  for (auto _ : state) {
    auto payload = tessera::detail::encodeTile(codec, tile.view(), options, nullptr, &scratch);
    if (!payload) {
      state.SkipWithError(payload.error().message.c_str());
      return;
    }
    payload_bytes = payload->size();
    benchmark::DoNotOptimize(payload->data());
  }
  setLabel(state, tile.texels.size(), payload_bytes);
  state.SetLabel(tessera::codecName(codec));
}

void BM_Decode(benchmark::State& state) {
  const Codec codec = Codec(state.range(0));
  const uint32_t side = uint32_t(state.range(1)), channels = uint32_t(state.range(2));
  const Image tile = makeImageLike(side, side, channels);
  CodecScratch scratch;
  auto payload =
      tessera::detail::encodeTile(codec, tile.view(), optionsFrom(state), nullptr, &scratch);
  if (!payload) {
    state.SkipWithError(payload.error().message.c_str());
    return;
  }
  Image out(side, side, channels);
  for (auto _ : state) {
    auto result = tessera::detail::decodeTile(codec, *payload, out, nullptr, &scratch);
    if (!result) {
      state.SkipWithError(result.error().message.c_str());
      return;
    }
    benchmark::DoNotOptimize(out.texels.data());
  }
  setLabel(state, tile.texels.size(), payload->size());
  state.SetLabel(tessera::codecName(codec));
}

void jpegTiles(benchmark::internal::Benchmark* b) {
  b->ArgNames({"codec", "side", "ch", "effort", "q"});
  for (int side : {256, 258}) b->Args({int(Codec::kJpeg), side, 3, 0, 85});
  b->Args({int(Codec::kJpeg), 256, 4, 0, 85});  // RGBA: JPEG plus the zstd alpha plane
  b->Args({int(Codec::kJpeg), 256, 1, 0, 85});
}

void allCodecs(benchmark::internal::Benchmark* b) {
  b->ArgNames({"codec", "side", "ch", "effort", "q"});
  for (Codec codec :
       {Codec::kRaw, Codec::kZstd, Codec::kLz4, Codec::kJpeg, Codec::kPng, Codec::kWebp})
    b->Args({int(codec), 256, 3, 0, 85});
  // The efforts that decide the defaults (docs/codecs.md).
  for (int effort : {3, 9}) b->Args({int(Codec::kZstd), 256, 3, effort, 85});
  for (int effort : {1, 6}) b->Args({int(Codec::kPng), 256, 3, effort, 85});
  for (int effort : {3, 6}) b->Args({int(Codec::kWebp), 256, 3, effort, 85});
  // The canonical RGBA tile for lossless codecs.
  for (Codec codec : {Codec::kZstd, Codec::kLz4, Codec::kPng, Codec::kWebp})
    b->Args({int(codec), 256, 4, 0, 85});
}

}  // namespace

BENCHMARK(BM_Encode)->Name("jpeg_tile_encode")->Apply(jpegTiles);
BENCHMARK(BM_Decode)->Name("jpeg_tile_decode")->Apply(jpegTiles);
BENCHMARK(BM_Encode)->Name("encode")->Apply(allCodecs);
BENCHMARK(BM_Decode)->Name("decode")->Apply(allCodecs);

BENCHMARK_MAIN();
