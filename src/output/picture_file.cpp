#include <tessera/picture_file.h>

#include <fmt/format.h>

#include "codecs/encode.h"
#include "output/output_file.h"

namespace tessera {

namespace {

Result<void> writePngOf(const ImageView& view, const std::string& path) {
  Result<std::vector<uint8_t>> png = detail::encodeTile(Codec::kPng, view, detail::EncodeOptions{});
  if (!png) return fail(png.error().code, fmt::format("{}: {}", path, png.error().message));
  return detail::writeFileAtomically(path, *png);
}

}  // namespace

Result<void> writePng(const Picture& picture, const std::string& path) {
  if (picture.width == 0 || picture.height == 0 ||
      picture.rgba.size() != size_t(picture.width) * picture.height * 4)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: cannot write a {}x{} picture of {} bytes as PNG", path,
                            picture.width, picture.height, picture.rgba.size()));
  return writePngOf(
      {picture.rgba.data(), picture.width, picture.height, 4, size_t(picture.width) * 4}, path);
}

Result<void> writePng(const Image& image, const std::string& path) {
  if (image.width_px == 0 || image.height_px == 0 || image.channels < 1 || image.channels > 4 ||
      image.texels.size() != size_t(image.width_px) * image.height_px * image.channels)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: cannot write a {}x{}x{} image of {} bytes as PNG", path,
                            image.width_px, image.height_px, image.channels, image.texels.size()));
  return writePngOf(image.view(), path);
}

}  // namespace tessera
