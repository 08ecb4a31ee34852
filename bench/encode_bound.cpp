// tessera-encode-bound: the speed limit of `tessera build` on an input, "JPEG-encode every tile
// of the pyramid on all cores" (issue 32). The pyramid's tiles are cut once, up front and
// untimed, with the builder's own streaming pyramid; then only the encoding is timed: the
// stored tiles the builder would encode (uniform ones are stored as a colour, not encoded) on
// N threads pulling from one counter, with the builder's settings. No reading, no pyramid, no
// spool, no layout, no fsync. `tessera build` time over this time says how close the build is.
//
//   tessera-encode-bound INPUT [--tile PX] [--quality Q] [--threads N] [--runs N] [--444]
//
// Holds every tile in memory: about 4/3 x width x height x channels bytes (1.1 GB for a
// 268-megapixel RGB image). Prints one line of JSON.

#include <sys/resource.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>

#include "builder/band_reader.h"
#include "builder/pyramid_builder.h"
#include "builder/tile_cutter.h"
#include "codecs/encode.h"

namespace tessera::detail {
namespace {

struct Options {
  std::string input;
  uint32_t tile_px = 256;
  int quality = 85;
  uint32_t threads = 0;
  int runs = 3;
  bool chroma_subsampling = true;
};

/// Keeps a copy of every tile the builder would encode (not uniform: every texel the first).
class KeepingSink final : public TileSink {
 public:
  explicit KeepingSink(const ImageInfo& info) : info_(info) {}
  Result<void> tileRowReady(uint32_t level, uint32_t tile_row, const LevelRows& rows) override {
    const size_t bytes = info_.storedTileBytes();
    for (uint32_t x = 0; x < info_.tilesX(level); ++x) {
      std::vector<uint8_t> tile(bytes);
      cutTile(rows, info_.tile_size_px, info_.border_px, x, tile_row, tile.data());
      bool uniform = true;
      for (size_t i = info_.channels; i < bytes && uniform; i += info_.channels)
        uniform = std::memcmp(tile.data(), tile.data() + i, info_.channels) == 0;
      if (uniform)
        ++uniform_tiles;
      else
        tiles.push_back(std::move(tile));
    }
    return {};
  }
  std::vector<std::vector<uint8_t>> tiles;
  uint64_t uniform_tiles = 0;

 private:
  const ImageInfo& info_;
};

Result<void> cutPyramid(const Options& options, ImageInfo& info, KeepingSink*& out_sink,
                        std::unique_ptr<KeepingSink>& owner) {
  TESSERA_ASSIGN_OR_RETURN(std::unique_ptr<BandReader> reader, openBandReader(options.input));
  const SourceInfo& source = reader->info();
  info.width_px = source.width_px;
  info.height_px = source.height_px;
  info.channels = source.channels;
  info.tile_size_px = options.tile_px;
  info.level_count = levelCountFor(info.width_px, info.height_px, info.tile_size_px);
  owner = std::make_unique<KeepingSink>(info);
  out_sink = owner.get();
  PyramidBuilder pyramid(info, *owner);
  const size_t row_bytes = size_t(info.width_px) * info.channels;
  for (uint32_t y = 0; y < info.height_px;) {
    std::span<uint8_t> slots = pyramid.rowsToFill(source.natural_band_rows);
    const uint32_t rows = uint32_t(slots.size() / row_bytes);
    TESSERA_TRY(reader->readRows(rows, slots));
    TESSERA_TRY(pyramid.commitRows(rows));
    y += rows;
  }
  return pyramid.finish();
}

/// User plus system CPU seconds of the whole process so far.
double cpuSeconds() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  auto seconds = [](const timeval& t) { return double(t.tv_sec) + t.tv_usec / 1e6; };
  return seconds(usage.ru_utime) + seconds(usage.ru_stime);
}

int run(const Options& options) {
  ImageInfo info;
  KeepingSink* sink = nullptr;
  std::unique_ptr<KeepingSink> owner;
  if (Result<void> cut = cutPyramid(options, info, sink, owner); !cut) {
    std::fprintf(stderr, "tessera-encode-bound: %s\n", cut.error().message.c_str());
    return 1;
  }
  const uint32_t threads =
      options.threads ? options.threads : std::max(1u, std::thread::hardware_concurrency());
  EncodeOptions encode_options;
  encode_options.quality = options.quality;
  encode_options.chroma_subsampling = options.chroma_subsampling;
  const uint32_t side = info.storedTileSidePx();
  std::vector<double> seconds;
  uint64_t payload_bytes = 0;
  // CPU time is the figure to compare on a busy machine, where wall time depends on how many
  // threads compete for the cores.
  const double cpu_before = cpuSeconds();
  for (int r = 0; r < options.runs; ++r) {
    std::atomic<size_t> next{0};
    std::atomic<uint64_t> bytes{0};
    std::atomic<bool> failed{false};
    const auto start = std::chrono::steady_clock::now();
    std::vector<std::thread> workers;
    for (uint32_t t = 0; t < threads; ++t) {
      workers.emplace_back([&] {
        CodecScratch scratch;
        uint64_t mine = 0;
        for (size_t i = next++; i < sink->tiles.size(); i = next++) {
          ImageView view{sink->tiles[i].data(), side, side, info.channels,
                         size_t(side) * info.channels};
          auto payload = encodeTile(Codec::kJpeg, view, encode_options, nullptr, &scratch);
          if (!payload)
            failed = true;
          else
            mine += payload->size();
        }
        bytes += mine;
      });
    }
    for (std::thread& worker : workers) worker.join();
    seconds.push_back(
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    if (failed) {
      std::fprintf(stderr, "tessera-encode-bound: a tile failed to encode\n");
      return 1;
    }
    payload_bytes = bytes;
  }
  const double cpu_per_run = (cpuSeconds() - cpu_before) / options.runs;
  std::sort(seconds.begin(), seconds.end());
  const double median = seconds[seconds.size() / 2];
  const double megapixels = double(info.width_px) * info.height_px / 1e6;
  fmt::print(
      "{{\"input\": \"{}\", \"width\": {}, \"height\": {}, \"tile\": {}, \"quality\": {}, "
      "\"threads\": {}, \"tiles_encoded\": {}, \"tiles_uniform\": {}, \"payload_bytes\": {}, "
      "\"encode_s_median\": {:.3f}, \"encode_s_min\": {:.3f}, \"encode_cpu_s\": {:.3f}, "
      "\"megapixels_per_s\": {:.1f}}}\n",
      options.input, info.width_px, info.height_px, info.tile_size_px, options.quality, threads,
      sink->tiles.size(), sink->uniform_tiles, payload_bytes, median, seconds.front(), cpu_per_run,
      megapixels / median);
  return 0;
}

}  // namespace
}  // namespace tessera::detail

int main(int argc, char** argv) {
  tessera::detail::Options options;
  auto number = [&](int& i) -> long {
    if (i + 1 >= argc) {
      std::fprintf(stderr, "tessera-encode-bound: %s needs a value\n", argv[i]);
      std::exit(2);
    }
    return std::strtol(argv[++i], nullptr, 10);
  };
  for (int i = 1; i < argc; ++i) {
    std::string arg = argv[i];
    if (arg == "--tile")
      options.tile_px = uint32_t(number(i));
    else if (arg == "--quality")
      options.quality = int(number(i));
    else if (arg == "--threads")
      options.threads = uint32_t(number(i));
    else if (arg == "--runs")
      options.runs = std::max(1, int(number(i)));
    else if (arg == "--444")
      options.chroma_subsampling = false;
    else if (!arg.empty() && arg[0] != '-' && options.input.empty())
      options.input = arg;
    else {
      std::fprintf(stderr,
                   "usage: tessera-encode-bound INPUT [--tile PX] [--quality Q] [--threads N] "
                   "[--runs N] [--444]\n");
      return 2;
    }
  }
  if (options.input.empty()) {
    std::fprintf(stderr, "tessera-encode-bound: no input (see the usage line with --help)\n");
    return 2;
  }
  return tessera::detail::run(options);
}
