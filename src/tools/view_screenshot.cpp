#include "tools/view_screenshot.h"

#include <filesystem>

#include <fmt/format.h>

#include "build/output_file.h"
#include "format/codec.h"

namespace tessera::cli {

Result<void> writeScreenshot(const Picture& picture, const std::string& path) {
  if (picture.width == 0 || picture.height == 0 ||
      picture.rgba.size() != size_t(picture.width) * picture.height * 4)
    return Unexpected(
        ErrorCode::kInvalidArgument,
        fmt::format("{}: no picture to write ({}x{})", path, picture.width, picture.height));
  // The PNG tile codec already writes whole PNG streams of any size.
  const ImageView view{picture.rgba.data(), picture.width, picture.height, 4,
                       size_t(picture.width) * 4};
  Result<std::vector<uint8_t>> png = detail::encodeTile(Codec::kPng, view, {});
  if (!png)
    return Unexpected(ErrorCode::kInternal,
                      fmt::format("{}: PNG encoding failed: {}", path, png.error().message));
  TESSERA_ASSIGN_OR_RETURN(detail::TempFile file, detail::TempFile::create(path));
  TESSERA_TRY(file.pwrite(0, *png));
  return file.commit();
}

std::string nextScreenshotPath(const std::string& dir) {
  for (uint32_t n = 1;; ++n) {
    std::string path =
        (std::filesystem::path(dir) / fmt::format("tessera-screenshot-{}.png", n)).string();
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) return path;
  }
}

}  // namespace tessera::cli
