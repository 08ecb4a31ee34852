// Archive::readRegion: assembles any rectangle of a level from the tiles under it.
#include <tessera/archive.h>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <mutex>
#include <thread>
#include <vector>

#include <fmt/format.h>

#include "archive_impl.h"

namespace tessera {

namespace {

constexpr uint32_t kMaxRegionSidePx = 16384;
constexpr size_t kTilesPerThread = 8;

}  // namespace

Result<Image> Archive::readRegion(uint32_t image, uint32_t level, const PixelRect& rect) const {
  if (image >= impl_->infos.size())
    return fail(ErrorCode::kInvalidArgument, fmt::format("{}: no image {}", impl_->name, image));
  const ImageInfo& info = impl_->infos[image];
  if (level >= info.level_count)
    return fail(ErrorCode::kInvalidArgument, fmt::format("{}: no level {} (image has {})",
                                                         impl_->name, level, info.level_count));
  if (rect.width == 0 || rect.height == 0)
    return fail(ErrorCode::kInvalidArgument, fmt::format("{}: empty rectangle", impl_->name));
  if (rect.width > kMaxRegionSidePx || rect.height > kMaxRegionSidePx)
    return fail(ErrorCode::kTooLarge,
                fmt::format("{}: region {}x{} exceeds {} px per side", impl_->name, rect.width,
                            rect.height, kMaxRegionSidePx));
  Image out(rect.width, rect.height, info.channels, info.sample_type);
  int64_t level_w = info.levelWidthPx(level), level_h = info.levelHeightPx(level);
  int64_t x0 = std::max<int64_t>(rect.x, 0), y0 = std::max<int64_t>(rect.y, 0);
  int64_t x1 = std::min<int64_t>(rect.x + rect.width, level_w);
  int64_t y1 = std::min<int64_t>(rect.y + rect.height, level_h);
  if (x0 >= x1 || y0 >= y1) return out;
  const int64_t t = info.tile_size_px;
  const int64_t tx0 = x0 / t, ty0 = y0 / t, tiles_x = (x1 - 1) / t - tx0 + 1;
  const size_t tiles = size_t(tiles_x) * size_t((y1 - 1) / t - ty0 + 1);
  // `texel` is in bytes, so one copy serves every sample type.
  const uint32_t b = info.border_px, texel = info.texelBytes();
  // Tile i (row-major over the covered tiles) into its part of `out`: tiles cover disjoint
  // texels of the region, so threads need no lock to write them.
  // Each thread decodes into one reused tile: a fresh 200 KiB tile per decode is an mmap, its
  // page faults and an munmap, a quarter of the time of a large read.
  struct Worker {
    CodecScratch scratch;
    Image tile;
  };
  auto readOne = [&](size_t i, Worker& worker) -> Result<void> {
    const int64_t tx = tx0 + int64_t(i % size_t(tiles_x)), ty = ty0 + int64_t(i / size_t(tiles_x));
    const TileId id{image, level, uint32_t(tx), uint32_t(ty)};
    TESSERA_ASSIGN_OR_RETURN(const TileEntry entry, tileEntry(id));
    std::vector<uint8_t> payload;
    if (entry.hasPayload()) {
      TESSERA_ASSIGN_OR_RETURN(payload, readPayload(id, entry));
    }
    TESSERA_TRY(decodeTileInto(id, entry, payload, worker.tile, &worker.scratch));
    const Image& tile = worker.tile;
    const int64_t cx0 = std::max(x0, tx * t), cx1 = std::min(x1, (tx + 1) * t);
    const int64_t cy0 = std::max(y0, ty * t), cy1 = std::min(y1, (ty + 1) * t);
    const size_t row_bytes = size_t(cx1 - cx0) * texel;
    for (int64_t y = cy0; y < cy1; ++y) {
      const uint8_t* src = tile.row(uint32_t(y - ty * t + b)) + (cx0 - tx * t + b) * texel;
      uint8_t* dst = out.row(uint32_t(y - rect.y)) + (cx0 - rect.x) * texel;
      std::memcpy(dst, src, row_bytes);
    }
    return {};
  };
  // Decoding dominates a large region (a 4096^2 window is 256 JPEG tiles), so the tiles are
  // shared out to a thread per core; a few tiles are not worth starting threads for.
  const size_t threads =
      std::min<size_t>(std::max(1u, std::thread::hardware_concurrency()), tiles / kTilesPerThread);
  if (threads <= 1) {
    Worker worker;
    for (size_t i = 0; i < tiles; ++i) TESSERA_TRY(readOne(i, worker));
    return out;
  }
  std::atomic<size_t> next{0};
  std::atomic<bool> failed{false};
  std::mutex error_mutex;
  size_t error_tile = SIZE_MAX;
  Error error;
  auto work = [&] {
    Worker worker;
    for (size_t i = next++; i < tiles && !failed; i = next++) {
      Result<void> done = readOne(i, worker);
      if (done) continue;
      failed = true;
      // The first failing tile in row-major order is the one reported, as a serial read would.
      std::lock_guard lock(error_mutex);
      if (i < error_tile) {
        error_tile = i;
        error = done.error();
      }
    }
  };
  {
    std::vector<std::jthread> helpers;
    for (size_t k = 1; k < threads; ++k) helpers.emplace_back(work);
    work();
  }
  if (error_tile != SIZE_MAX) return Unexpected(std::move(error));
  return out;
}

Result<Image> Archive::readRegionRgba(uint32_t image, uint32_t level, const PixelRect& rect) const {
  if (image < impl_->infos.size() && impl_->infos[image].sample_type != SampleType::kU8)
    return fail(ErrorCode::kUnsupported,
                fmt::format("{}: image {} has {} samples; read them with readRegion, or map them "
                            "to 8 bits with a display window first",
                            impl_->name, image, sampleTypeName(impl_->infos[image].sample_type)));
  TESSERA_ASSIGN_OR_RETURN(Image native, readRegion(image, level, rect));
  if (native.channels == 4) return native;
  Image rgba(native.width_px, native.height_px, 4);
  // Texels outside the level were zero-filled in `native`; keep them transparent.
  int64_t level_w = impl_->infos[image].levelWidthPx(level);
  int64_t level_h = impl_->infos[image].levelHeightPx(level);
  size_t pixels = size_t(native.width_px) * native.height_px;
  for (size_t i = 0; i < pixels; ++i) {
    const uint8_t* s = &native.texels[i * native.channels];
    uint8_t* d = &rgba.texels[i * 4];
    int64_t x = rect.x + int64_t(i % native.width_px), y = rect.y + int64_t(i / native.width_px);
    bool inside = x >= 0 && y >= 0 && x < level_w && y < level_h;
    switch (native.channels) {
      case 1:
        d[0] = d[1] = d[2] = s[0];
        d[3] = inside ? 255 : 0;
        break;
      case 2:
        d[0] = d[1] = d[2] = s[0];
        d[3] = s[1];
        break;
      case 3:
        d[0] = s[0];
        d[1] = s[1];
        d[2] = s[2];
        d[3] = inside ? 255 : 0;
        break;
    }
  }
  return rgba;
}

}  // namespace tessera
