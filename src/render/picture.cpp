// Pictures: comparison (PSNR, maximum and mean difference).
#include <cmath>
#include <cstdlib>
#include <limits>

#include <fmt/format.h>

#include <tessera/render.h>

namespace tessera {

namespace {

bool wellFormed(const Picture& picture) {
  return picture.rgba.size() == size_t(picture.width) * picture.height * 4;
}

}  // namespace

Result<PictureDifference> comparePictures(const Picture& a, const Picture& b) {
  if (a.width != b.width || a.height != b.height)
    return fail(ErrorCode::kInvalidArgument, fmt::format("pictures differ in size: {}x{} and {}x{}",
                                                         a.width, a.height, b.width, b.height));
  if (!wellFormed(a) || !wellFormed(b))
    return fail(
        ErrorCode::kInvalidArgument,
        fmt::format("a {}x{} picture needs {} bytes of RGBA, got {} and {}", a.width, a.height,
                    size_t(a.width) * a.height * 4, a.rgba.size(), b.rgba.size()));
  PictureDifference difference;
  uint64_t sum_abs = 0, sum_squares = 0;
  uint32_t max_abs = 0;
  for (size_t i = 0; i < a.rgba.size(); ++i) {
    const uint32_t d = uint32_t(std::abs(int(a.rgba[i]) - int(b.rgba[i])));
    sum_abs += d;
    sum_squares += uint64_t(d) * d;
    max_abs = std::max(max_abs, d);
  }
  const double samples = double(a.rgba.size());
  difference.max_abs = max_abs;
  difference.mean_abs = samples > 0 ? double(sum_abs) / samples : 0;
  // PSNR = 10 log10(255^2 / MSE), the mean over every channel of every pixel.
  difference.psnr_db = sum_squares == 0
                           ? std::numeric_limits<double>::infinity()
                           : 10 * std::log10(255.0 * 255.0 * samples / double(sum_squares));
  return difference;
}

}  // namespace tessera
