// Whole-slide images through OpenSlide (Aperio, Hamamatsu, Leica, MIRAX, Ventana, generic
// tiled TIFF): OpenSlide gives the levels and the decoded pixels. It never hands out stored
// tiles, so for the TIFF-based vendors (generic-tiff, aperio) the file is also opened as a
// pyramidal TIFF and a level whose directory holds fitting JPEG tiles is copied through libtiff;
// every other level is decoded by OpenSlide.

#include <algorithm>
#include <cmath>
#include <cstring>

#include <fmt/format.h>

#include "file_reader.h"
#include "pyramid_source.h"

#if TESSERA_HAVE_OPENSLIDE
#include <openslide.h>
#endif

namespace tessera::detail {

#if TESSERA_HAVE_OPENSLIDE
namespace {

// Rows per openslide_read_region call: 64 rows of a 200000-px slide are 51 MiB of ARGB.
constexpr uint32_t kSlideBandRows = 64;

struct SlideCloser {
  void operator()(openslide_t* slide) const { openslide_close(slide); }
};
using SlideHandle = std::shared_ptr<openslide_t>;

/// One slide level's pixels, composited over white (OpenSlide's ARGB is premultiplied; a slide's
/// transparent area is where nothing was scanned, which viewers show as background).
class SlideLevelReader final : public BandReader {
 public:
  SlideLevelReader(SlideHandle slide, std::string path, uint32_t level, double downsample,
                   SourceInfo info)
      : slide_(std::move(slide)),
        path_(std::move(path)),
        level_(level),
        downsample_(downsample),
        info_(std::move(info)) {}
  const SourceInfo& info() const override { return info_; }

  Result<void> readRows(uint32_t rows, std::span<uint8_t> out) override {
    for (uint32_t done = 0; done < rows;) {
      const uint32_t take = std::min(kSlideBandRows, rows - done);
      argb_.resize(size_t(info_.width_px) * take);
      const int64_t y0 = int64_t(std::llround(double(next_row_) * downsample_));
      openslide_read_region(slide_.get(), argb_.data(), 0, y0, int32_t(level_), info_.width_px,
                            take);
      if (const char* error = openslide_get_error(slide_.get()))
        return fail(ErrorCode::kCorrupt,
                    fmt::format("{}: level {} rows {}..{}: OpenSlide: {}", path_, level_, next_row_,
                                next_row_ + take, error));
      uint8_t* dst = out.data() + size_t(done) * info_.width_px * 3;
      for (size_t i = 0; i < argb_.size(); ++i) {
        const uint32_t p = argb_[i];
        const uint32_t background = 255 - (p >> 24);
        dst[3 * i] = uint8_t(((p >> 16) & 0xFF) + background);
        dst[3 * i + 1] = uint8_t(((p >> 8) & 0xFF) + background);
        dst[3 * i + 2] = uint8_t((p & 0xFF) + background);
      }
      done += take;
      next_row_ += take;
    }
    return {};
  }

 private:
  SlideHandle slide_;
  std::string path_;
  uint32_t level_;
  double downsample_;
  SourceInfo info_;
  std::vector<uint32_t> argb_;
  uint32_t next_row_ = 0;
};

class SlidePyramid final : public PyramidSource {
 public:
  SlidePyramid(SlideHandle slide, std::string path)
      : slide_(std::move(slide)), path_(std::move(path)) {}

  Result<void> open();
  const SourceInfo& info() const override { return info_; }
  const std::vector<SourceLevel>& levels() const override { return levels_; }
  Result<SourceTile> readTile(uint32_t level, uint32_t x, uint32_t y) override {
    return tiff_->readTile(uint32_t(tiff_level_[level]), x, y);
  }
  Result<std::unique_ptr<BandReader>> openLevel(uint32_t level) override {
    SourceInfo info = info_;
    info.width_px = levels_[level].width_px;
    info.height_px = levels_[level].height_px;
    return std::unique_ptr<BandReader>(std::make_unique<SlideLevelReader>(
        slide_, path_, level, openslide_get_level_downsample(slide_.get(), int32_t(level)),
        std::move(info)));
  }

 private:
  // For TIFF-based vendors, the TIFF level of each slide level with the same size, if any.
  void matchTiffLevels(const std::string& vendor);

  SlideHandle slide_;
  std::string path_;
  SourceInfo info_;
  std::vector<SourceLevel> levels_;
  std::unique_ptr<PyramidSource> tiff_;
  std::vector<int> tiff_level_;
};

Result<void> SlidePyramid::open() {
  const int32_t count = openslide_get_level_count(slide_.get());
  for (int32_t l = 0; l < count; ++l) {
    int64_t width = 0, height = 0;
    openslide_get_level_dimensions(slide_.get(), l, &width, &height);
    if (l == 0) TESSERA_TRY(checkSourceDimensions(path_, uint64_t(width), uint64_t(height)));
    if (width <= 0 || height <= 0)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: slide level {} is {}x{} px", path_, l, width, height));
    levels_.push_back({uint32_t(width), uint32_t(height), 0, false});
  }
  if (const char* error = openslide_get_error(slide_.get()))
    return fail(ErrorCode::kCorrupt, fmt::format("{}: OpenSlide: {}", path_, error));
  const char* vendor = openslide_get_property_value(slide_.get(), OPENSLIDE_PROPERTY_NAME_VENDOR);
  info_.width_px = levels_[0].width_px;
  info_.height_px = levels_[0].height_px;
  info_.channels = 3;
  info_.natural_band_rows = kSlideBandRows;
  info_.buffer_bytes = uint64_t(info_.width_px) * kSlideBandRows * 4;
  info_.format = "openslide";
  info_.metadata["openslide"] = {{"vendor", vendor ? vendor : ""}, {"levels", levels_.size()}};
  for (const char* name : {"openslide.mpp-x", "openslide.mpp-y", "openslide.objective-power"}) {
    if (const char* value = openslide_get_property_value(slide_.get(), name))
      info_.metadata["openslide"][name] = value;
  }
  matchTiffLevels(vendor ? vendor : "");
  return {};
}

void SlidePyramid::matchTiffLevels(const std::string& vendor) {
  tiff_level_.assign(levels_.size(), -1);
  if (vendor != "generic-tiff" && vendor != "aperio") return;
  auto tiff = openTiffPyramid(path_);
  // Not a pyramid libtiff sees, or not RGB: OpenSlide decodes every level.
  if (!tiff || !*tiff || (*tiff)->info().channels != 3) return;
  const std::vector<SourceLevel>& tiff_levels = (*tiff)->levels();
  for (size_t l = 0; l < levels_.size(); ++l) {
    for (size_t t = 0; t < tiff_levels.size(); ++t) {
      if (tiff_levels[t].width_px == levels_[l].width_px &&
          tiff_levels[t].height_px == levels_[l].height_px && tiff_levels[t].jpeg_tiles) {
        tiff_level_[l] = int(t);
        levels_[l].tile_size_px = tiff_levels[t].tile_size_px;
        levels_[l].jpeg_tiles = true;
        break;
      }
    }
  }
  tiff_ = std::move(*tiff);
}

}  // namespace

Result<std::unique_ptr<PyramidSource>> openSlide(const std::string& path) {
  TESSERA_TRY(checkSourceFile(path));
  openslide_t* opened = openslide_open(path.c_str());
  if (!opened)
    return fail(ErrorCode::kUnsupported,
                path + ": not a slide OpenSlide can read (no vendor format recognised)");
  SlideHandle slide(opened, SlideCloser());
  if (const char* error = openslide_get_error(opened))
    return fail(ErrorCode::kCorrupt, fmt::format("{}: OpenSlide: {}", path, error));
  auto pyramid = std::make_unique<SlidePyramid>(std::move(slide), path);
  TESSERA_TRY(pyramid->open());
  return std::unique_ptr<PyramidSource>(std::move(pyramid));
}

#else

Result<std::unique_ptr<PyramidSource>> openSlide(const std::string& path) {
  return fail(ErrorCode::kUnsupported,
              path +
                  ": whole-slide images need OpenSlide, which this build was made without "
                  "(install libopenslide-dev and reconfigure)");
}

#endif

}  // namespace tessera::detail
