#include "support/archive_fixture.h"

#include <gtest/gtest.h>

#include "builder/band_reader.h"
#include "format/checksum.h"
#include "format/header.h"
#include "support/test_images.h"

namespace tessera::test {

std::string writeImagePng(const std::string& path, const Image& image) {
  static constexpr PngColour kColours[] = {PngColour::kGray, PngColour::kGrayAlpha, PngColour::kRgb,
                                           PngColour::kRgba};
  PngSpec spec;
  spec.width_px = image.width_px;
  spec.height_px = image.height_px;
  spec.colour = kColours[image.channels - 1];
  return writePng(path, spec, image.texels);
}

Image readSource(const std::string& source) {
  auto reader = detail::openBandReader(source);
  if (!reader) {
    ADD_FAILURE() << reader.error().message;
    return {};
  }
  const detail::SourceInfo& info = (*reader)->info();
  Image image(info.width_px, info.height_px, info.channels);
  std::string error;
  image.texels = readAllRows(**reader, 256, &error);
  EXPECT_EQ(error, "");
  return image;
}

Image readImagePng(const std::string& path) {
  return readSource(path);
}

BuiltArchive buildFromImage(const Image& image, BuildOptions options, const std::string& dir,
                            const std::string& name) {
  BuiltArchive built;
  std::string source = dir + "source.png";
  std::string written = writeImagePng(source, image);
  if (!written.empty()) {
    ADD_FAILURE() << written;
    return built;
  }
  options.inputs = {source};
  options.output = dir + name;
  auto report = buildArchive(options);
  if (!report) {
    ADD_FAILURE() << report.error().message;
    return built;
  }
  built.path = options.output;
  built.bytes = readFileBytes(built.path);
  return built;
}

std::vector<uint8_t> withMetadata(std::vector<uint8_t> bytes, const std::string& json) {
  Result<detail::FileHeader> header = detail::decodeHeader(bytes, "withMetadata");
  if (!header) {
    ADD_FAILURE() << header.error().message;
    return bytes;
  }
  const std::span<const uint8_t> block(reinterpret_cast<const uint8_t*>(json.data()), json.size());
  header->metadata = {bytes.size(), block.size(), detail::checksum64(block)};
  bytes.insert(bytes.end(), block.begin(), block.end());
  header->file_bytes = bytes.size();
  const std::vector<uint8_t> sealed = detail::encodeHeader(*header);
  std::copy(sealed.begin(), sealed.end(), bytes.begin());
  return bytes;
}

void rewriteMetadata(const std::string& path, const std::string& json) {
  ASSERT_TRUE(writeFileBytes(path, withMetadata(readFileBytes(path), json)))
      << path << ": cannot rewrite";
}

}  // namespace tessera::test
