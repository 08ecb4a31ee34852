#pragma once
// What the JPEG codec's two sides share: the payload layout (docs/codecs.md, "jpeg") and the
// TurboJPEG handle rule.

#include <cstddef>
#include <cstdint>

#include <turbojpeg.h>

namespace tessera::detail::jpeg {

inline constexpr const char* kWhat = "jpeg payload";
/// JPEG stores dimensions in 16 bits and libjpeg refuses sides above JPEG_MAX_DIMENSION.
inline constexpr uint32_t kMaxJpegSidePx = 65500;
/// 2 and 4 channels: a u32 LE JPEG length, the JPEG, then the alpha plane as one zstd frame.
inline constexpr size_t kAlphaLengthBytes = 4;

inline bool hasAlpha(uint32_t channels) {
  return channels == 2 || channels == 4;
}
inline uint32_t colourComponents(uint32_t channels) {
  return channels <= 2 ? 1 : 3;
}

// libjpeg keeps tables and state in its decompressor across images, and after a failed
// decode that state can make the next, valid stream fail too (found by codec_fuzzer: a bad
// Huffman table poisoned the following tile). A handle that has seen an error is therefore
// dropped; errors are rare, so recreating it costs nothing measurable.
inline void dropHandle(void*& handle) {
  if (handle != nullptr) tjDestroy(handle);
  handle = nullptr;
}

}  // namespace tessera::detail::jpeg
