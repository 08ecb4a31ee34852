#include "support/test_images.h"

#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <jpeglib.h>
#include <png.h>
#include <tiffio.h>
#include <unistd.h>
#include <zlib.h>

namespace tessera::test {
namespace {

const TIFFFieldInfo kGeoFields[] = {
    {33550, TIFF_VARIABLE2, TIFF_VARIABLE2, TIFF_DOUBLE, FIELD_CUSTOM, 1, 1,
     const_cast<char*>("ModelPixelScale")},
    {33922, TIFF_VARIABLE2, TIFF_VARIABLE2, TIFF_DOUBLE, FIELD_CUSTOM, 1, 1,
     const_cast<char*>("ModelTiepoint")},
    {34264, TIFF_VARIABLE2, TIFF_VARIABLE2, TIFF_DOUBLE, FIELD_CUSTOM, 1, 1,
     const_cast<char*>("ModelTransformation")},
    {34735, TIFF_VARIABLE2, TIFF_VARIABLE2, TIFF_SHORT, FIELD_CUSTOM, 1, 1,
     const_cast<char*>("GeoKeyDirectory")},
    {34736, TIFF_VARIABLE2, TIFF_VARIABLE2, TIFF_DOUBLE, FIELD_CUSTOM, 1, 1,
     const_cast<char*>("GeoDoubleParams")},
    {34737, TIFF_VARIABLE, TIFF_VARIABLE, TIFF_ASCII, FIELD_CUSTOM, 1, 0,
     const_cast<char*>("GeoAsciiParams")},
    {42112, TIFF_VARIABLE, TIFF_VARIABLE, TIFF_ASCII, FIELD_CUSTOM, 1, 0,
     const_cast<char*>("GDALMetadata")},
    {42113, TIFF_VARIABLE, TIFF_VARIABLE, TIFF_ASCII, FIELD_CUSTOM, 1, 0,
     const_cast<char*>("GDALNoDataValue")},
};

std::string g_tiff_error;  // test helpers run on the test thread only

void onTiffWriteError(const char* module, const char* fmt, va_list args) {
  char text[512];
  std::vsnprintf(text, sizeof(text), fmt, args);
  g_tiff_error = fmt::format("{}: {}", module ? module : "libtiff", text);
}

// Widens an 8-bit sample to the fixture's sample type, written in native byte order.
void putSample(uint8_t* dst, uint8_t value, const TiffSpec& spec) {
  if (spec.bits == 8) {
    *dst = value;
  } else if (spec.bits == 16) {
    const uint16_t wide = uint16_t(value * 257);
    std::memcpy(dst, &wide, 2);
  } else if (spec.sample_format == SAMPLEFORMAT_IEEEFP) {
    const float wide = float(value) / 255.0f;
    std::memcpy(dst, &wide, 4);
  } else {
    const uint32_t wide = uint32_t(value) * 16843009u;
    std::memcpy(dst, &wide, 4);
  }
}

struct TiffCloser {
  void operator()(TIFF* tif) const { TIFFClose(tif); }
};

}  // namespace

std::vector<uint8_t> makeTestPixels(uint32_t width_px, uint32_t height_px, uint32_t channels,
                                    uint32_t seed) {
  std::vector<uint8_t> pixels(size_t(width_px) * height_px * channels);
  uint32_t state = seed * 2654435761u + 12345u;
  size_t i = 0;
  for (uint32_t y = 0; y < height_px; ++y) {
    for (uint32_t x = 0; x < width_px; ++x) {
      for (uint32_t c = 0; c < channels; ++c) {
        state = state * 1664525u + 1013904223u;
        const uint32_t noise = (state >> 28) & 7;
        const uint32_t base = x * (2 + c) + y * (3 + c) + c * 40;
        // A triangle wave, not a wrap-around: no hard edges for JPEG to ring on.
        const uint32_t folded = (base + noise) % 510;
        pixels[i++] = uint8_t(folded > 255 ? 510 - folded : folded);
      }
    }
  }
  return pixels;
}

std::string writeTiff(const std::string& path, const TiffSpec& spec,
                      const std::vector<uint8_t>& pixels) {
  const size_t expected = size_t(spec.width_px) * spec.height_px * spec.samples;
  if (pixels.size() != expected)
    return fmt::format("{} pixel bytes, expected {}", pixels.size(), expected);
  TIFFErrorHandler previous = TIFFSetErrorHandler(onTiffWriteError);
  g_tiff_error.clear();
  std::unique_ptr<TIFF, TiffCloser> tif(TIFFOpen(path.c_str(), spec.bigtiff ? "w8" : "w"));
  auto failure = [&](const std::string& what) {
    TIFFSetErrorHandler(previous);
    return fmt::format("{}: {} {}", path, what, g_tiff_error);
  };
  if (!tif) return failure("cannot create");
  TIFF* t = tif.get();
  TIFFSetField(t, TIFFTAG_IMAGEWIDTH, spec.width_px);
  TIFFSetField(t, TIFFTAG_IMAGELENGTH, spec.height_px);
  TIFFSetField(t, TIFFTAG_SAMPLESPERPIXEL, spec.samples);
  TIFFSetField(t, TIFFTAG_BITSPERSAMPLE, spec.bits);
  TIFFSetField(t, TIFFTAG_SAMPLEFORMAT, spec.sample_format);
  TIFFSetField(t, TIFFTAG_PLANARCONFIG, spec.planar);
  TIFFSetField(t, TIFFTAG_COMPRESSION, spec.compression);
  const bool ycbcr = spec.compression == COMPRESSION_JPEG && spec.photometric == PHOTOMETRIC_RGB &&
                     spec.jpeg_ycbcr && spec.planar == PLANARCONFIG_CONTIG;
  TIFFSetField(t, TIFFTAG_PHOTOMETRIC, ycbcr ? PHOTOMETRIC_YCBCR : spec.photometric);
  if (spec.compression == COMPRESSION_JPEG) {
    TIFFSetField(t, TIFFTAG_JPEGQUALITY, spec.jpeg_quality);
    if (ycbcr) TIFFSetField(t, TIFFTAG_JPEGCOLORMODE, JPEGCOLORMODE_RGB);
  }
  if (spec.predictor != PREDICTOR_NONE) TIFFSetField(t, TIFFTAG_PREDICTOR, spec.predictor);
  if (spec.photometric == PHOTOMETRIC_PALETTE) {
    std::vector<uint16_t> map(size_t(1) << spec.bits);
    for (size_t i = 0; i < map.size(); ++i) map[i] = uint16_t(i * 257);
    TIFFSetField(t, TIFFTAG_COLORMAP, map.data(), map.data(), map.data());
  }
  if (spec.photometric == PHOTOMETRIC_SEPARATED) TIFFSetField(t, TIFFTAG_INKSET, INKSET_CMYK);
  const uint16_t colour = spec.photometric == PHOTOMETRIC_RGB         ? 3
                          : spec.photometric == PHOTOMETRIC_SEPARATED ? 4
                          : spec.photometric == PHOTOMETRIC_YCBCR     ? 3
                                                                      : 1;
  if (spec.samples > colour) {
    std::vector<uint16_t> extra = spec.extra_sample_types;
    while (extra.size() < size_t(spec.samples - colour)) {
      extra.push_back(extra.empty() ? EXTRASAMPLE_UNASSALPHA : EXTRASAMPLE_UNSPECIFIED);
    }
    TIFFSetField(t, TIFFTAG_EXTRASAMPLES, uint16_t(extra.size()), extra.data());
  }
  const GeoTags& geo = spec.geo;
  const bool has_geo = !geo.model_pixel_scale.empty() || !geo.model_tiepoint.empty() ||
                       !geo.model_transformation.empty() || !geo.geo_key_directory.empty() ||
                       !geo.geo_double_params.empty() || !geo.geo_ascii_params.empty() ||
                       !geo.gdal_metadata.empty() || !geo.gdal_nodata.empty();
  if (has_geo) {
    for (const TIFFFieldInfo& info : kGeoFields) {
      if (!TIFFFindField(t, info.field_tag, TIFF_ANY)) TIFFMergeFieldInfo(t, &info, 1);
    }
    auto doubles = [&](ttag_t tag, const std::vector<double>& v) {
      if (!v.empty()) TIFFSetField(t, tag, uint32_t(v.size()), v.data());
    };
    doubles(33550, geo.model_pixel_scale);
    doubles(33922, geo.model_tiepoint);
    doubles(34264, geo.model_transformation);
    doubles(34736, geo.geo_double_params);
    if (!geo.geo_key_directory.empty()) {
      TIFFSetField(t, 34735, uint32_t(geo.geo_key_directory.size()), geo.geo_key_directory.data());
    }
    if (!geo.geo_ascii_params.empty()) TIFFSetField(t, 34737, geo.geo_ascii_params.c_str());
    if (!geo.gdal_metadata.empty()) TIFFSetField(t, 42112, geo.gdal_metadata.c_str());
    if (!geo.gdal_nodata.empty()) TIFFSetField(t, 42113, geo.gdal_nodata.c_str());
  }

  const uint32_t bytes_per_sample = spec.bits / 8;
  const bool separate = spec.planar == PLANARCONFIG_SEPARATE;
  const uint32_t planes = separate ? spec.samples : 1;
  const uint32_t unit_samples = separate ? 1 : spec.samples;
  // Copies the block [x0, x0 + w) x [y0, y0 + h) of one plane into `unit`, row pitch `pitch` px.
  auto pack = [&](std::vector<uint8_t>* unit, uint32_t plane, uint32_t x0, uint32_t y0, uint32_t w,
                  uint32_t h, uint32_t pitch) {
    for (uint32_t r = 0; r < h && y0 + r < spec.height_px; ++r) {
      for (uint32_t c = 0; c < w && x0 + c < spec.width_px; ++c) {
        for (uint32_t s = 0; s < unit_samples; ++s) {
          const uint32_t sample = separate ? plane : s;
          const uint8_t v =
              pixels[(size_t(y0 + r) * spec.width_px + x0 + c) * spec.samples + sample];
          putSample(unit->data() + ((size_t(r) * pitch + c) * unit_samples + s) * bytes_per_sample,
                    v, spec);
        }
      }
    }
  };
  if (spec.tiled) {
    TIFFSetField(t, TIFFTAG_TILEWIDTH, spec.tile_width_px);
    TIFFSetField(t, TIFFTAG_TILELENGTH, spec.tile_height_px);
    std::vector<uint8_t> unit(size_t(TIFFTileSize64(t)));
    for (uint32_t plane = 0; plane < planes; ++plane) {
      for (uint32_t y = 0; y < spec.height_px; y += spec.tile_height_px) {
        for (uint32_t x = 0; x < spec.width_px; x += spec.tile_width_px) {
          std::fill(unit.begin(), unit.end(), 0);
          pack(&unit, plane, x, y, spec.tile_width_px, spec.tile_height_px, spec.tile_width_px);
          if (TIFFWriteTile(t, unit.data(), x, y, 0, uint16_t(plane)) < 0) {
            return failure(fmt::format("cannot write tile at ({}, {})", x, y));
          }
        }
      }
    }
  } else {
    TIFFSetField(t, TIFFTAG_ROWSPERSTRIP, spec.rows_per_strip);
    std::vector<uint8_t> unit(size_t(TIFFScanlineSize64(t)));
    for (uint32_t plane = 0; plane < planes; ++plane) {
      for (uint32_t y = 0; y < spec.height_px; ++y) {
        pack(&unit, plane, 0, y, spec.width_px, 1, spec.width_px);
        if (TIFFWriteScanline(t, unit.data(), y, uint16_t(plane)) < 0) {
          return failure(fmt::format("cannot write row {}", y));
        }
      }
    }
  }
  if (!TIFFWriteDirectory(t)) return failure("cannot write directory");
  tif.reset();
  TIFFSetErrorHandler(previous);
  return g_tiff_error.empty() ? "" : path + ": " + g_tiff_error;
}

std::vector<uint8_t> makeRawTiffHeader(uint32_t width_px, uint32_t height_px, uint32_t data_bytes) {
  std::vector<uint8_t> out;
  auto u16 = [&](uint16_t v) {
    out.push_back(uint8_t(v));
    out.push_back(uint8_t(v >> 8));
  };
  auto u32 = [&](uint32_t v) {
    u16(uint16_t(v));
    u16(uint16_t(v >> 16));
  };
  struct Entry {
    uint16_t tag, type;
    uint32_t value;
  };
  const Entry entries[] = {
      {256, 4, width_px}, {257, 4, height_px}, {258, 3, 8},
      {259, 3, 1},        {262, 3, 1},         {273, 4, 0 /* patched below */},
      {277, 3, 1},        {278, 4, height_px}, {279, 4, data_bytes},
  };
  const uint32_t entry_count = uint32_t(std::size(entries));
  const uint32_t data_offset = 8 + 2 + entry_count * 12 + 4;
  out.insert(out.end(), {'I', 'I', 42, 0});
  u32(8);
  u16(uint16_t(entry_count));
  for (const Entry& e : entries) {
    u16(e.tag);
    u16(e.type);
    u32(1);
    const uint32_t value = e.tag == 273 ? data_offset : e.value;
    if (e.type == 3) {
      u16(uint16_t(value));
      u16(0);
    } else {
      u32(value);
    }
  }
  u32(0);
  out.resize(out.size() + data_bytes, 0x80);
  return out;
}

namespace {

struct PngWriteError {
  std::jmp_buf jump;
  char message[256] = {};
};

void onPngWriteError(png_structp png, png_const_charp message) {
  auto* error = static_cast<PngWriteError*>(png_get_error_ptr(png));
  std::snprintf(error->message, sizeof(error->message), "%s", message);
  std::longjmp(error->jump, 1);
}

// Only trivial locals: libpng longjmps out of here on error.
bool writePngRows(std::FILE* file, const PngSpec* spec, const uint8_t* packed, size_t row_bytes,
                  PngWriteError* error) {
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, error, onPngWriteError, nullptr);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!info) return false;
  if (setjmp(error->jump)) {
    png_destroy_write_struct(&png, &info);
    return false;
  }
  png_init_io(png, file);
  png_set_IHDR(png, info, spec->width_px, spec->height_px, spec->bit_depth, int(spec->colour),
               spec->interlaced ? PNG_INTERLACE_ADAM7 : PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  if (spec->colour == PngColour::kPalette) {
    png_color entries[256];
    const int count = int(spec->palette.size() / 3);
    for (int i = 0; i < count; ++i) {
      entries[i] = {spec->palette[3 * i], spec->palette[3 * i + 1], spec->palette[3 * i + 2]};
    }
    png_set_PLTE(png, info, entries, count);
    if (!spec->transparency.empty()) {
      png_byte alpha[256];
      for (size_t i = 0; i < spec->transparency.size(); ++i)
        alpha[i] = png_byte(spec->transparency[i]);
      png_set_tRNS(png, info, alpha, int(spec->transparency.size()), nullptr);
    }
  } else if (!spec->transparency.empty()) {
    png_color_16 colour{};
    colour.gray = spec->transparency[0];
    if (spec->transparency.size() >= 3) {
      colour.red = spec->transparency[0];
      colour.green = spec->transparency[1];
      colour.blue = spec->transparency[2];
    }
    png_set_tRNS(png, info, nullptr, 0, &colour);
  }
  png_write_info(png, info);
  const int passes = spec->interlaced ? png_set_interlace_handling(png) : 1;
  for (int pass = 0; pass < passes; ++pass) {
    for (uint32_t y = 0; y < spec->height_px; ++y) {
      png_write_row(png, packed + y * row_bytes);
    }
  }
  png_write_end(png, info);
  png_destroy_write_struct(&png, &info);
  return true;
}

}  // namespace

std::string writePng(const std::string& path, const PngSpec& spec,
                     const std::vector<uint8_t>& pixels) {
  const uint32_t samples = spec.colour == PngColour::kGray || spec.colour == PngColour::kPalette ? 1
                           : spec.colour == PngColour::kGrayAlpha                                ? 2
                           : spec.colour == PngColour::kRgb                                      ? 3
                                                            : 4;
  if (pixels.size() != size_t(spec.width_px) * spec.height_px * samples) return "bad pixel count";
  // Pack rows into PNG's layout: big-endian 16-bit, or several samples per byte under 8 bits.
  const size_t row_bits = size_t(spec.width_px) * samples * spec.bit_depth;
  const size_t row_bytes = (row_bits + 7) / 8;
  std::vector<uint8_t> packed(row_bytes * spec.height_px, 0);
  for (uint32_t y = 0; y < spec.height_px; ++y) {
    uint8_t* row = packed.data() + y * row_bytes;
    for (size_t i = 0; i < size_t(spec.width_px) * samples; ++i) {
      const uint8_t v = pixels[y * size_t(spec.width_px) * samples + i];
      if (spec.bit_depth == 16) {
        row[2 * i] = v;
        row[2 * i + 1] = v;
      } else if (spec.bit_depth == 8) {
        row[i] = v;
      } else {
        const size_t bit = i * spec.bit_depth;
        row[bit / 8] |= uint8_t(v << (8 - spec.bit_depth - bit % 8));
      }
    }
  }
  std::FILE* file = std::fopen(path.c_str(), "wb");
  if (!file) return path + ": cannot create";
  PngWriteError error;
  const bool ok = writePngRows(file, &spec, packed.data(), row_bytes, &error);
  std::fclose(file);
  return ok ? "" : path + ": " + error.message;
}

std::vector<uint8_t> makePngHeaderOnly(uint32_t width_px, uint32_t height_px) {
  std::vector<uint8_t> out = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  auto u32 = [&](uint32_t v) {
    for (int shift = 24; shift >= 0; shift -= 8) out.push_back(uint8_t(v >> shift));
  };
  auto chunk = [&](const char* type, const std::vector<uint8_t>& data) {
    u32(uint32_t(data.size()));
    const size_t start = out.size();
    out.insert(out.end(), type, type + 4);
    out.insert(out.end(), data.begin(), data.end());
    u32(uint32_t(crc32(0, out.data() + start, uInt(out.size() - start))));
  };
  std::vector<uint8_t> ihdr;
  for (uint32_t v : {width_px, height_px}) {
    for (int shift = 24; shift >= 0; shift -= 8) ihdr.push_back(uint8_t(v >> shift));
  }
  ihdr.insert(ihdr.end(), {8, 2, 0, 0, 0});
  chunk("IHDR", ihdr);
  chunk("IDAT", {});
  chunk("IEND", {});
  return out;
}

namespace {

struct JpegWriteError {
  jpeg_error_mgr base;
  std::jmp_buf jump;
};

void onJpegWriteError(j_common_ptr cinfo) {
  std::longjmp(reinterpret_cast<JpegWriteError*>(cinfo->err)->jump, 1);
}

bool writeJpegRows(std::FILE* file, const JpegSpec* spec, const uint8_t* pixels) {
  jpeg_compress_struct cinfo{};
  JpegWriteError error{};
  cinfo.err = jpeg_std_error(&error.base);
  error.base.error_exit = onJpegWriteError;
  if (setjmp(error.jump)) {
    jpeg_destroy_compress(&cinfo);
    return false;
  }
  jpeg_create_compress(&cinfo);
  jpeg_stdio_dest(&cinfo, file);
  cinfo.image_width = spec->width_px;
  cinfo.image_height = spec->height_px;
  cinfo.input_components = int(spec->components);
  cinfo.in_color_space = spec->components == 1   ? JCS_GRAYSCALE
                         : spec->components == 4 ? JCS_CMYK
                                                 : JCS_RGB;
  jpeg_set_defaults(&cinfo);
  jpeg_set_quality(&cinfo, spec->quality, TRUE);
  if (spec->progressive) jpeg_simple_progression(&cinfo);
  jpeg_start_compress(&cinfo, TRUE);
  const size_t row_bytes = size_t(spec->width_px) * spec->components;
  while (cinfo.next_scanline < cinfo.image_height) {
    JSAMPROW row = const_cast<uint8_t*>(pixels + cinfo.next_scanline * row_bytes);
    jpeg_write_scanlines(&cinfo, &row, 1);
  }
  jpeg_finish_compress(&cinfo);
  jpeg_destroy_compress(&cinfo);
  return true;
}

}  // namespace

std::string writeJpeg(const std::string& path, const JpegSpec& spec,
                      const std::vector<uint8_t>& pixels) {
  if (pixels.size() != size_t(spec.width_px) * spec.height_px * spec.components) {
    return "bad pixel count";
  }
  std::FILE* file = std::fopen(path.c_str(), "wb");
  if (!file) return path + ": cannot create";
  const bool ok = writeJpegRows(file, &spec, pixels.data());
  std::fclose(file);
  return ok ? "" : path + ": libjpeg failed";
}

std::vector<uint8_t> readFileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<uint8_t>(std::istreambuf_iterator<char>(in), {});
}

bool writeFileBytes(const std::string& path, const std::vector<uint8_t>& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
  return bool(out);
}

std::string testTempDir() {
  const ::testing::TestInfo* test = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = test ? fmt::format("{}.{}", test->test_suite_name(), test->name()) : "none";
  for (char& c : name) {
    if (c == '/') c = '_';
  }
  const std::filesystem::path dir =
      std::filesystem::path(::testing::TempDir()) / fmt::format("tessera_{}_{}", ::getpid(), name);
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir.string() + "/";
}

}  // namespace tessera::test
