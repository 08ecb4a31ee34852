// Pictures: comparison (PSNR, maximum and mean difference) and PNG output.
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>

#include <fmt/format.h>

#include <tessera/render.h>

#include "format/codec.h"

namespace tessera {

namespace {

bool wellFormed(const Picture& picture) {
  return picture.rgba.size() == size_t(picture.width) * picture.height * 4;
}

/// Writes all of `bytes` to `fd`, retrying short writes and interrupts.
bool writeAll(int fd, const std::vector<uint8_t>& bytes) {
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    done += size_t(n);
  }
  return true;
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

Result<void> writePng(const Picture& picture, const std::string& path) {
  if (picture.width == 0 || picture.height == 0 || !wellFormed(picture))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: cannot write a {}x{} picture of {} bytes as PNG", path,
                            picture.width, picture.height, picture.rgba.size()));
  const ImageView view{picture.rgba.data(), picture.width, picture.height, 4,
                       size_t(picture.width) * 4};
  Result<std::vector<uint8_t>> png = detail::encodeTile(Codec::kPng, view, detail::EncodeOptions{});
  if (!png) return fail(png.error().code, fmt::format("{}: {}", path, png.error().message));
  // A temporary beside the final path, renamed over it once complete.
  std::string temp_path = path + ".XXXXXX";
  const int fd = ::mkstemp(temp_path.data());
  if (fd < 0)
    return fail(ErrorCode::kIo,
                fmt::format("{}: cannot create a temporary file: {}", path, std::strerror(errno)));
  // mkstemp creates 0600; a picture is for others to view (umask is process-wide state we
  // must not flip under other threads, so the mode is fixed).
  ::fchmod(fd, 0644);
  const bool written = writeAll(fd, *png);
  const int write_errno = errno;
  const bool closed = ::close(fd) == 0;
  if (!written || !closed) {
    ::unlink(temp_path.c_str());
    return fail(ErrorCode::kIo, fmt::format("{}: write failed: {}", path,
                                            std::strerror(written ? errno : write_errno)));
  }
  if (::rename(temp_path.c_str(), path.c_str()) != 0) {
    const int rename_errno = errno;
    ::unlink(temp_path.c_str());
    return fail(ErrorCode::kIo,
                fmt::format("{}: cannot rename into place: {}", path, std::strerror(rename_errno)));
  }
  return {};
}

}  // namespace tessera
