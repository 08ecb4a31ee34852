// A mosaic of image files placed by a manifest, read as one image (docs/builder.md, "Mosaic
// manifests"). Slide scanners and satellite strips deliver images of differing sizes at
// arbitrary, possibly overlapping, offsets, which a regular grid (grid_reader.cpp) cannot hold.
#include "mosaic_reader.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>

#include <fmt/format.h>

#include "file_reader.h"
#include "mosaic_manifest.h"

namespace tessera::detail {
namespace {

/// A failure inside one entry, prefixed with the manifest and the entry's index, so that a
/// member's own message ("a.tif: no such file") says which manifest and entry named it.
Unexpected inEntry(const MosaicManifest& manifest, size_t index, const Error& error) {
  return Unexpected(error.code,
                    fmt::format("{}: images[{}]: {}", manifest.path, index, error.message));
}

/// Fills `out` with `pixels` copies of the background pixel `background` (pixel_bytes).
void fillPixels(uint8_t* out, size_t pixels, const std::vector<uint8_t>& background) {
  for (size_t i = 0; i < pixels; ++i)
    std::memcpy(out + i * background.size(), background.data(), background.size());
}

/// Reads the images crossing each band, in manifest order so that later entries overwrite
/// earlier ones. Images are opened at their first band and closed after their last one.
class MosaicReader final : public BandReader {
 public:
  explicit MosaicReader(MosaicManifest manifest) : manifest_(std::move(manifest)) {}

  Result<void> open();
  const SourceInfo& info() const override { return info_; }
  Result<void> readRows(uint32_t rows, std::span<uint8_t> out) override;
  Result<void> skipRows(uint32_t rows) override;
  uint64_t storedBytesRead() const override {
    uint64_t bytes = closed_bytes_read_;
    for (const auto& [index, reader] : active_)
      if (reader) bytes += reader->storedBytesRead();
    return bytes;
  }

 private:
  /// Checks image `index`'s file against the manifest and the first image.
  Result<void> checkImage(size_t index, const SourceInfo& file) const;
  /// The canvas, the background pixel, the buffers estimate; after every image is checked.
  Result<void> describe();
  /// Moves the images that start above row `end` into active_, except those ending at or above
  /// `alive_below` (passed over by a skip: never opened).
  void admit(uint32_t end, uint32_t alive_below);
  /// Closes the active images ending at or above row `row`.
  void retire(uint32_t row);
  /// Opens image `index` at canvas row `row` (skipping its rows above).
  Result<std::unique_ptr<BandReader>> openAt(size_t index, uint32_t row) const;
  uint32_t bottom(size_t index) const {
    return manifest_.images[index].y_px + manifest_.images[index].height_px;
  }

  MosaicManifest manifest_;  // image sides filled in from the files at open()
  SourceInfo info_;
  std::vector<uint8_t> background_;  // one pixel, in the sample type, host byte order
  std::vector<size_t> by_top_;       // image indices by top row, manifest order among ties
  size_t next_top_ = 0;              // by_top_[next_top_..] not yet admitted
  /// Images admitted and not yet past: index -> reader, null until first read. Ordered by
  /// index, which is the drawing order.
  std::map<size_t, std::unique_ptr<BandReader>> active_;
  uint32_t next_row_ = 0;
  uint64_t closed_bytes_read_ = 0;
  std::vector<uint8_t> piece_;  // rows of one image, before they are placed
};

Result<void> MosaicReader::checkImage(size_t index, const SourceInfo& file) const {
  const MosaicImage& image = manifest_.images[index];
  const bool width_differs = image.width_px != 0 && image.width_px != file.width_px;
  const bool height_differs = image.height_px != 0 && image.height_px != file.height_px;
  if (width_differs || height_differs)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: the manifest states a {} of {} px, the file is {}x{} px",
                            manifest_.where(index), width_differs ? "width" : "height",
                            width_differs ? image.width_px : image.height_px, file.width_px,
                            file.height_px));
  if (index > 0 && (file.channels != info_.channels || file.sample_type != info_.sample_type))
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: {} channel(s) of {} samples; a mosaic's images must all match "
                            "images[0] ({}: {} channel(s) of {} samples)",
                            manifest_.where(index), file.channels, sampleTypeName(file.sample_type),
                            manifest_.images[0].path_text, info_.channels,
                            sampleTypeName(info_.sample_type)));
  return {};
}

Result<void> MosaicReader::open() {
  // Every image is opened once here (its header only) and closed again, so that a missing or
  // mismatched file fails the build before anything is written.
  for (size_t i = 0; i < manifest_.images.size(); ++i) {
    Result<std::unique_ptr<BandReader>> file = openImageFileReader(manifest_.images[i].path);
    if (!file) return inEntry(manifest_, i, file.error());
    const SourceInfo& file_info = (*file)->info();
    if (i == 0) {
      info_.channels = file_info.channels;
      info_.sample_type = file_info.sample_type;
      info_.natural_band_rows = file_info.natural_band_rows;
    }
    TESSERA_TRY(checkImage(i, file_info));
    MosaicImage& image = manifest_.images[i];
    image.width_px = file_info.width_px;
    image.height_px = file_info.height_px;
    info_.natural_band_rows =
        std::min({info_.natural_band_rows, file_info.natural_band_rows, file_info.height_px});
    info_.buffer_bytes = std::max(info_.buffer_bytes, file_info.buffer_bytes);
  }
  return describe();
}

/// Background values must be representable: whole numbers within range for integer samples.
Result<std::vector<uint8_t>> backgroundPixel(const MosaicManifest& manifest,
                                             const SourceInfo& info) {
  const size_t sample_bytes = sampleBytes(info.sample_type);
  std::vector<uint8_t> pixel(info.channels * sample_bytes, 0);
  if (manifest.background.empty()) return pixel;
  if (manifest.background.size() != info.channels)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: \"background\" has {} value(s), the images {} channel(s)",
                            manifest.path, manifest.background.size(), info.channels));
  const double high = info.sample_type == SampleType::kU8 ? 255 : 65535;
  for (size_t c = 0; c < info.channels; ++c) {
    const double value = manifest.background[c];
    uint8_t* sample = pixel.data() + c * sample_bytes;
    if (info.sample_type == SampleType::kF32) {
      const float f = float(value);
      std::memcpy(sample, &f, 4);
      continue;
    }
    if (value < 0 || value > high || value != std::floor(value))
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: \"background\" value {} is not a whole number 0..{} for {} "
                              "samples",
                              manifest.path, value, high, sampleTypeName(info.sample_type)));
    if (info.sample_type == SampleType::kU8) {
      *sample = uint8_t(value);
    } else {
      const uint16_t u = uint16_t(value);
      std::memcpy(sample, &u, 2);
    }
  }
  return pixel;
}

Result<void> MosaicReader::describe() {
  uint64_t extent_x = 0, extent_y = 0;
  for (const MosaicImage& image : manifest_.images) {
    extent_x = std::max(extent_x, uint64_t(image.x_px) + image.width_px);
    extent_y = std::max(extent_y, uint64_t(image.y_px) + image.height_px);
  }
  const uint64_t width = manifest_.width_px ? manifest_.width_px : extent_x;
  const uint64_t height = manifest_.height_px ? manifest_.height_px : extent_y;
  TESSERA_TRY(checkSourceDimensions(manifest_.path, width, height));
  for (size_t i = 0; i < manifest_.images.size(); ++i) {
    const MosaicImage& image = manifest_.images[i];
    if (uint64_t(image.x_px) + image.width_px > width ||
        uint64_t(image.y_px) + image.height_px > height)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: {}x{} px at ({}, {}) reaches past the canvas of {}x{} px",
                              manifest_.where(i), image.width_px, image.height_px, image.x_px,
                              image.y_px, width, height));
  }
  info_.width_px = uint32_t(width);
  info_.height_px = uint32_t(height);
  TESSERA_ASSIGN_OR_RETURN(background_, backgroundPixel(manifest_, info_));

  by_top_.resize(manifest_.images.size());
  for (size_t i = 0; i < by_top_.size(); ++i) by_top_[i] = i;
  std::stable_sort(by_top_.begin(), by_top_.end(), [&](size_t a, size_t b) {
    return manifest_.images[a].y_px < manifest_.images[b].y_px;
  });
  // The readers' buffers at the busiest row (a sweep over image tops and bottoms; an image's
  // own buffer is at most the largest seen), plus the one image's rows placed at a time.
  std::vector<std::pair<uint32_t, int>> edges;
  uint32_t widest = 0;
  for (size_t i = 0; i < manifest_.images.size(); ++i) {
    edges.push_back({manifest_.images[i].y_px, 1});
    edges.push_back({bottom(i), -1});
    widest = std::max(widest, manifest_.images[i].width_px);
  }
  // At a shared row the opening counts first: a band crossing it holds both images.
  std::sort(edges.begin(), edges.end(), [](const auto& a, const auto& b) {
    return a.first < b.first || (a.first == b.first && a.second > b.second);
  });
  int64_t crossing = 0, most_open = 0;
  for (const auto& [row, change] : edges) most_open = std::max(most_open, crossing += change);
  const size_t pixel_bytes = background_.size();
  info_.buffer_bytes = uint64_t(most_open) * info_.buffer_bytes +
                       uint64_t(widest) * info_.natural_band_rows * pixel_bytes;
  info_.format = "mosaic";
  info_.metadata = {{"mosaic",
                     {{"manifest", manifest_.path},
                      {"images", manifest_.images.size()},
                      {"background", manifest_.background}}}};
  return {};
}

void MosaicReader::admit(uint32_t end, uint32_t alive_below) {
  for (; next_top_ < by_top_.size() && manifest_.images[by_top_[next_top_]].y_px < end;
       ++next_top_) {
    const size_t index = by_top_[next_top_];
    if (bottom(index) > alive_below) active_.emplace(index, nullptr);
  }
}

void MosaicReader::retire(uint32_t row) {
  for (auto it = active_.begin(); it != active_.end();) {
    if (bottom(it->first) > row) {
      ++it;
      continue;
    }
    if (it->second) closed_bytes_read_ += it->second->storedBytesRead();
    it = active_.erase(it);
  }
}

Result<std::unique_ptr<BandReader>> MosaicReader::openAt(size_t index, uint32_t row) const {
  const MosaicImage& image = manifest_.images[index];
  Result<std::unique_ptr<BandReader>> file = openImageFileReader(image.path);
  if (!file) return inEntry(manifest_, index, file.error());
  const SourceInfo& file_info = (*file)->info();
  // Replaced since open()? The placement was checked for the old size.
  if (file_info.width_px != image.width_px || file_info.height_px != image.height_px ||
      file_info.channels != info_.channels || file_info.sample_type != info_.sample_type)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: the file changed during the build (now {}x{} px, {} channel(s))",
                            manifest_.where(index), file_info.width_px, file_info.height_px,
                            file_info.channels));
  if (row > image.y_px) {
    Result<void> skipped = (*file)->skipRows(row - image.y_px);
    if (!skipped) return inEntry(manifest_, index, skipped.error());
  }
  return file;
}

Result<void> MosaicReader::readRows(uint32_t rows, std::span<uint8_t> out) {
  TESSERA_CHECK(rows > 0 && rows <= info_.height_px - next_row_)
      << manifest_.path << ": readRows(" << rows << ") at row " << next_row_;
  const size_t pixel_bytes = background_.size();
  const size_t row_bytes = size_t(info_.width_px) * pixel_bytes;
  TESSERA_CHECK(out.size() >= rows * row_bytes) << manifest_.path << ": output span too small";
  const uint32_t first = next_row_, end = next_row_ + rows;
  fillPixels(out.data(), size_t(info_.width_px) * rows, background_);
  admit(end, first);
  for (auto& [index, reader] : active_) {
    const MosaicImage& image = manifest_.images[index];
    const uint32_t top = std::max(first, image.y_px);
    const uint32_t take = std::min(end, bottom(index)) - top;
    if (!reader) {
      TESSERA_ASSIGN_OR_RETURN(reader, openAt(index, top));
    }
    const size_t image_row_bytes = size_t(image.width_px) * pixel_bytes;
    piece_.resize(image_row_bytes * take);
    Result<void> read = reader->readRows(take, piece_);
    if (!read) return inEntry(manifest_, index, read.error());
    for (uint32_t y = 0; y < take; ++y)
      std::memcpy(out.data() + (top - first + y) * row_bytes + image.x_px * pixel_bytes,
                  piece_.data() + y * image_row_bytes, image_row_bytes);
  }
  retire(end);
  next_row_ = end;
  return {};
}

Result<void> MosaicReader::skipRows(uint32_t rows) {
  TESSERA_CHECK(rows <= info_.height_px - next_row_)
      << manifest_.path << ": skipRows(" << rows << ") at row " << next_row_;
  const uint32_t target = next_row_ + rows;
  retire(target);
  // Open images reaching past the target skip to it (a TIFF seeks); the others open there.
  for (auto& [index, reader] : active_) {
    const uint32_t from = std::max(next_row_, manifest_.images[index].y_px);
    if (!reader || target <= from) continue;
    Result<void> skipped = reader->skipRows(target - from);
    if (!skipped) return inEntry(manifest_, index, skipped.error());
  }
  admit(target, target);
  next_row_ = target;
  return {};
}

}  // namespace

Result<std::unique_ptr<BandReader>> openMosaicReader(const std::string& path) {
  TESSERA_ASSIGN_OR_RETURN(MosaicManifest manifest, readMosaicManifest(path));
  auto reader = std::make_unique<MosaicReader>(std::move(manifest));
  TESSERA_TRY(reader->open());
  return std::unique_ptr<BandReader>(std::move(reader));
}

}  // namespace tessera::detail
