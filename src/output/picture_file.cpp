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

void putU16(std::vector<uint8_t>& out, uint16_t value) {
  out.push_back(uint8_t(value));
  out.push_back(uint8_t(value >> 8));
}

void putU32(std::vector<uint8_t>& out, uint32_t value) {
  for (int shift = 0; shift < 32; shift += 8) out.push_back(uint8_t(value >> shift));
}

// One IFD entry of a SHORT or LONG tag whose values fit in the entry (count 1, or 2 SHORTs).
void putEntry(std::vector<uint8_t>& out, uint16_t tag, uint16_t type, uint32_t count,
              uint32_t value) {
  putU16(out, tag);
  putU16(out, type);
  putU32(out, count);
  putU32(out, value);
}

// A baseline little-endian TIFF: one uncompressed strip, then the IFD, then the per-sample
// arrays that do not fit in their entries. Hand-written because it is this small and keeps
// libtiff out of the output module.
std::vector<uint8_t> encodeTiff(const Image& image) {
  constexpr uint16_t kShort = 3, kLong = 4;
  const uint32_t spp = image.channels;
  const uint16_t bits = uint16_t(8 * sampleBytes(image.sample_type));
  const uint16_t format = image.sample_type == SampleType::kF32 ? 3 : 1;  // IEEE float : uint
  const bool alpha = spp == 2 || spp == 4;
  const uint32_t data_bytes = uint32_t(image.texels.size());
  const uint32_t ifd_offset = 8 + ((data_bytes + 1) & ~1u);
  const uint16_t entries = alpha ? 12 : 11;
  const uint32_t arrays_offset = ifd_offset + 2 + entries * 12 + 4;
  // SHORT arrays of more than two values live after the IFD: BitsPerSample, then SampleFormat.
  auto perSample = [&](uint16_t value, uint32_t array_index) {
    return spp <= 2 ? uint32_t(value) | (spp == 2 ? uint32_t(value) << 16 : 0)
                    : arrays_offset + array_index * 2 * spp;
  };
  std::vector<uint8_t> out = {'I', 'I', 42, 0};
  putU32(out, ifd_offset);
  out.insert(out.end(), image.texels.begin(), image.texels.end());
  if (out.size() < ifd_offset) out.push_back(0);
  putU16(out, entries);
  putEntry(out, 256, kLong, 1, image.width_px);
  putEntry(out, 257, kLong, 1, image.height_px);
  putEntry(out, 258, kShort, spp, perSample(bits, 0));
  putEntry(out, 259, kShort, 1, 1);                 // no compression
  putEntry(out, 262, kShort, 1, spp >= 3 ? 2 : 1);  // RGB or min-is-black
  putEntry(out, 273, kLong, 1, 8);
  putEntry(out, 277, kShort, 1, spp);
  putEntry(out, 278, kLong, 1, image.height_px);
  putEntry(out, 279, kLong, 1, data_bytes);
  putEntry(out, 284, kShort, 1, 1);             // contiguous
  if (alpha) putEntry(out, 338, kShort, 1, 2);  // unassociated alpha
  putEntry(out, 339, kShort, spp, perSample(format, 1));
  putU32(out, 0);  // no next IFD
  if (spp > 2) {
    for (uint32_t c = 0; c < spp; ++c) putU16(out, bits);
    for (uint32_t c = 0; c < spp; ++c) putU16(out, format);
  }
  return out;
}

bool imageIsWhole(const Image& image) {
  return image.width_px != 0 && image.height_px != 0 && image.channels >= 1 &&
         image.channels <= 4 &&
         image.texels.size() == size_t(image.width_px) * image.height_px * image.texelBytes();
}

}  // namespace

Result<void> writeTiff(const Image& image, const std::string& path) {
  if (!imageIsWhole(image))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: cannot write a {}x{}x{} image of {} bytes as TIFF", path,
                            image.width_px, image.height_px, image.channels, image.texels.size()));
  // Classic TIFF offsets are 32-bit; 16384^2 RGBA f32 regions would need BigTIFF.
  if (image.texels.size() > (uint64_t(1) << 32) - (1 << 20))
    return fail(ErrorCode::kTooLarge,
                fmt::format("{}: {} bytes of texels exceed a classic TIFF's 4 GiB", path,
                            image.texels.size()));
  return detail::writeFileAtomically(path, encodeTiff(image));
}

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
  if (!imageIsWhole(image))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: cannot write a {}x{}x{} image of {} bytes as PNG", path,
                            image.width_px, image.height_px, image.channels, image.texels.size()));
  return writePngOf(image.view(), path);
}

}  // namespace tessera
