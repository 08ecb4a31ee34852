// tessera-make-tiff: writes a synthetic image (see src/build/synthetic_reader.h) of any size
// as a tiled or striped TIFF/BigTIFF, for benchmarks that need real multi-gigapixel inputs.
// Streams one band of tile (or strip) height at a time, so memory is width x band x channels
// whatever the height: a 32768 x 32768 RGB image (1 GP, 3 GiB) needs about 24 MiB.
//
//   tessera-make-tiff OUT.tif WIDTHxHEIGHT [--seed N] [--channels 3|4] [--tile PX | --strip ROWS]
//                     [--bigtiff | --classic] [--compression none|deflate|lzw] [--dry-run]
//
// --dry-run only generates the pixels and reports the generator's speed. --verify reads the
// written file back through Tessera's band reader, compares every row with the generator and
// reports the reader's speed.

#include <chrono>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <tiffio.h>

#include "builder/band_reader.h"

namespace {

struct Options {
  std::string output;
  std::string size;
  uint64_t seed = 1;
  uint32_t channels = 3;
  uint32_t tile_px = 256;  // 0 when striped
  uint32_t strip_rows = 0;
  int bigtiff = -1;  // -1 automatic, 0 classic, 1 BigTIFF
  uint16_t compression = COMPRESSION_NONE;
  bool dry_run = false;
  bool verify = false;
};

// Classic TIFF offsets are 32-bit; leave room for the directory and the offset arrays.
constexpr uint64_t kClassicLimitBytes = 4000000000ull;

void onTiffError(const char* module, const char* fmt, va_list args) {
  std::fprintf(stderr, "tessera-make-tiff: libtiff: %s: ", module ? module : "");
  std::vfprintf(stderr, fmt, args);
  std::fprintf(stderr, "\n");
}

int usage(const char* why) {
  std::fprintf(stderr,
               "tessera-make-tiff: %s\nusage: tessera-make-tiff OUT.tif WIDTHxHEIGHT [--seed N] "
               "[--channels 3|4] [--tile PX | --strip ROWS] [--bigtiff | --classic] "
               "[--compression none|deflate|lzw] [--dry-run] [--verify]\n",
               why);
  return 2;
}

bool parseArgs(int argc, char** argv, Options* options, std::string* error) {
  std::vector<std::string> positional;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        *error = arg + " needs a value";
        return "";
      }
      return argv[++i];
    };
    try {
      if (arg == "--seed") {
        options->seed = std::stoull(value());
      } else if (arg == "--channels") {
        options->channels = uint32_t(std::stoul(value()));
      } else if (arg == "--tile") {
        options->tile_px = uint32_t(std::stoul(value()));
        options->strip_rows = 0;
      } else if (arg == "--strip") {
        options->strip_rows = uint32_t(std::stoul(value()));
        options->tile_px = 0;
      } else if (arg == "--bigtiff") {
        options->bigtiff = 1;
      } else if (arg == "--classic") {
        options->bigtiff = 0;
      } else if (arg == "--compression") {
        const std::string name = value();
        if (name == "none") {
          options->compression = COMPRESSION_NONE;
        } else if (name == "deflate") {
          options->compression = COMPRESSION_ADOBE_DEFLATE;
        } else if (name == "lzw") {
          options->compression = COMPRESSION_LZW;
        } else {
          *error = "unknown compression " + name;
        }
      } else if (arg == "--verify") {
        options->verify = true;
      } else if (arg == "--dry-run") {
        options->dry_run = true;
      } else if (arg.starts_with("--")) {
        *error = "unknown option " + arg;
      } else {
        positional.push_back(arg);
      }
    } catch (const std::exception&) {
      *error = "bad number for " + arg;
    }
    if (!error->empty()) return false;
  }
  if (positional.size() != 2) {
    *error = "expected OUT.tif and WIDTHxHEIGHT";
    return false;
  }
  options->output = positional[0];
  options->size = positional[1];
  if (options->channels != 3 && options->channels != 4) *error = "--channels must be 3 or 4";
  if (options->tile_px != 0 && (options->tile_px % 16 != 0 || options->tile_px > 4096)) {
    *error = "--tile must be a multiple of 16, at most 4096";
  }
  if (options->tile_px == 0 && options->strip_rows == 0) *error = "--strip must be at least 1";
  return error->empty();
}

}  // namespace

int main(int argc, char** argv) {
  Options options;
  std::string error;
  if (!parseArgs(argc, argv, &options, &error)) return usage(error.c_str());
  const std::string source =
      fmt::format("synthetic:{}:{}:{}", options.size, options.seed, options.channels);
  auto opened = tessera::detail::openBandReader(source);
  if (!opened) {
    std::fprintf(stderr, "tessera-make-tiff: %s\n", opened.error().message.c_str());
    return 1;
  }
  tessera::detail::BandReader& reader = **opened;
  const uint32_t width = reader.info().width_px;
  const uint32_t height = reader.info().height_px;
  const uint32_t channels = reader.info().channels;
  const bool tiled = options.tile_px != 0;
  const uint32_t band_rows = std::min(height, tiled ? options.tile_px : options.strip_rows);
  const size_t row_bytes = size_t(width) * channels;
  const uint64_t image_bytes = uint64_t(row_bytes) * height;
  const bool bigtiff =
      options.bigtiff == 1 || (options.bigtiff == -1 && image_bytes > kClassicLimitBytes);
  if (!bigtiff && image_bytes > kClassicLimitBytes && !options.dry_run) {
    std::fprintf(stderr,
                 "tessera-make-tiff: %s: %llu bytes of pixels need BigTIFF (drop --classic)\n",
                 options.output.c_str(), static_cast<unsigned long long>(image_bytes));
    return 1;
  }

  TIFF* tif = nullptr;
  if (!options.dry_run) {
    TIFFSetErrorHandler(onTiffError);
    tif = TIFFOpen(options.output.c_str(), bigtiff ? "w8" : "w");
    if (!tif) {
      std::fprintf(stderr, "tessera-make-tiff: %s: cannot create\n", options.output.c_str());
      return 1;
    }
    TIFFSetField(tif, TIFFTAG_IMAGEWIDTH, width);
    TIFFSetField(tif, TIFFTAG_IMAGELENGTH, height);
    TIFFSetField(tif, TIFFTAG_SAMPLESPERPIXEL, uint16_t(channels));
    TIFFSetField(tif, TIFFTAG_BITSPERSAMPLE, uint16_t(8));
    TIFFSetField(tif, TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_RGB);
    TIFFSetField(tif, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG);
    TIFFSetField(tif, TIFFTAG_COMPRESSION, options.compression);
    if (options.compression != COMPRESSION_NONE)
      TIFFSetField(tif, TIFFTAG_PREDICTOR, PREDICTOR_HORIZONTAL);
    if (channels == 4) {
      const uint16_t extra = EXTRASAMPLE_UNASSALPHA;
      TIFFSetField(tif, TIFFTAG_EXTRASAMPLES, uint16_t(1), &extra);
    }
    if (tiled) {
      TIFFSetField(tif, TIFFTAG_TILEWIDTH, options.tile_px);
      TIFFSetField(tif, TIFFTAG_TILELENGTH, options.tile_px);
    } else {
      TIFFSetField(tif, TIFFTAG_ROWSPERSTRIP, band_rows);
    }
    TIFFSetField(tif, TIFFTAG_SOFTWARE, "tessera-make-tiff");
    TIFFSetField(tif, TIFFTAG_IMAGEDESCRIPTION, source.c_str());
  }

  std::vector<uint8_t> band(row_bytes * band_rows);
  std::vector<uint8_t> tile(tiled ? size_t(options.tile_px) * options.tile_px * channels : 0);
  const auto start = std::chrono::steady_clock::now();
  double generate_s = 0;
  int last_percent = -1;
  for (uint32_t y = 0; y < height; y += band_rows) {
    const uint32_t rows = std::min(band_rows, height - y);
    const auto band_start = std::chrono::steady_clock::now();
    auto read = reader.readRows(rows, std::span<uint8_t>(band.data(), rows * row_bytes));
    generate_s +=
        std::chrono::duration<double>(std::chrono::steady_clock::now() - band_start).count();
    if (!read) {
      std::fprintf(stderr, "tessera-make-tiff: %s\n", read.error().message.c_str());
      if (tif) TIFFClose(tif);
      return 1;
    }
    bool written = true;
    if (tif && tiled) {
      const size_t tile_row_bytes = size_t(options.tile_px) * channels;
      for (uint32_t x = 0; x < width && written; x += options.tile_px) {
        const uint32_t cols = std::min(options.tile_px, width - x);
        std::fill(tile.begin(), tile.end(), 0);  // padding past the image edges
        for (uint32_t r = 0; r < rows; ++r) {
          std::memcpy(tile.data() + r * tile_row_bytes,
                      band.data() + r * row_bytes + size_t(x) * channels, size_t(cols) * channels);
        }
        written = TIFFWriteEncodedTile(tif, TIFFComputeTile(tif, x, y, 0, 0), tile.data(),
                                       tmsize_t(tile.size())) >= 0;
      }
    } else if (tif) {
      written = TIFFWriteEncodedStrip(tif, TIFFComputeStrip(tif, y, 0), band.data(),
                                      tmsize_t(rows * row_bytes)) >= 0;
    }
    if (!written) {
      std::fprintf(stderr, "tessera-make-tiff: %s: write failed at row %u\n",
                   options.output.c_str(), y);
      TIFFClose(tif);
      return 1;
    }
    const int percent = int(uint64_t(y + rows) * 100 / height);
    if (percent / 5 != last_percent / 5) {
      std::fprintf(stderr, "\r%3d%%", percent);
      last_percent = percent;
    }
  }
  if (tif) {
    if (!TIFFWriteDirectory(tif)) {
      std::fprintf(stderr, "tessera-make-tiff: %s: cannot write the directory\n",
                   options.output.c_str());
      TIFFClose(tif);
      return 1;
    }
    TIFFClose(tif);
  }
  const double total_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const double megapixels = double(width) * height / 1e6;
  std::fprintf(stderr,
               "\r%s: %ux%u x%u (%s%s), %.0f MP in %.2f s: generate %.1f MP/s, total %.1f MP/s\n",
               options.dry_run ? "(dry run)" : options.output.c_str(), width, height, channels,
               tiled ? fmt::format("tiles {}", options.tile_px).c_str()
                     : fmt::format("strips {}", band_rows).c_str(),
               bigtiff ? ", BigTIFF" : "", megapixels, total_s, megapixels / generate_s,
               megapixels / total_s);
  if (options.verify && !options.dry_run) {
    // Read back in the reader's natural bands, timing the reader alone.
    auto file = tessera::detail::openBandReader(options.output);
    auto again = tessera::detail::openBandReader(source);
    if (!file || !again) {
      std::fprintf(stderr, "tessera-make-tiff: verify: %s\n",
                   (!file ? file.error() : again.error()).message.c_str());
      return 1;
    }
    const uint32_t verify_rows = (*file)->info().natural_band_rows;
    std::vector<uint8_t> got(row_bytes * verify_rows), want(row_bytes * verify_rows);
    double read_s = 0;
    for (uint32_t y = 0; y < height; y += verify_rows) {
      const uint32_t rows = std::min(verify_rows, height - y);
      const std::span<uint8_t> got_span(got.data(), rows * row_bytes);
      const auto read_start = std::chrono::steady_clock::now();
      auto read = (*file)->readRows(rows, got_span);
      read_s +=
          std::chrono::duration<double>(std::chrono::steady_clock::now() - read_start).count();
      if (!read) {
        std::fprintf(stderr, "tessera-make-tiff: verify: %s\n", read.error().message.c_str());
        return 1;
      }
      if (!(*again)->readRows(rows, std::span<uint8_t>(want.data(), rows * row_bytes)) ||
          std::memcmp(got.data(), want.data(), rows * row_bytes) != 0) {
        std::fprintf(stderr, "tessera-make-tiff: verify: %s differs from %s in rows %u..%u\n",
                     options.output.c_str(), source.c_str(), y, y + rows - 1);
        return 1;
      }
    }
    std::fprintf(stderr, "verified: read back in bands of %u rows at %.1f MP/s (%.0f MB/s)\n",
                 verify_rows, megapixels / read_s, double(image_bytes) / 1e6 / read_s);
  }
  return 0;
}
