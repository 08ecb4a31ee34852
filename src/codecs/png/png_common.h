#pragma once
// What the PNG codec's two sides share: the colour type of a channel count and the libpng
// error handling (docs/codecs.md, "png").

#include <csetjmp>
#include <cstdint>
#include <cstdio>
#include <vector>

#include <png.h>

namespace tessera::detail::png {

inline constexpr const char* kWhat = "png payload";

inline int colourType(uint32_t channels) {
  switch (channels) {
    case 1: return PNG_COLOR_TYPE_GRAY;
    case 2: return PNG_COLOR_TYPE_GRAY_ALPHA;
    case 3: return PNG_COLOR_TYPE_RGB;
    default: return PNG_COLOR_TYPE_RGB_ALPHA;
  }
}

// libpng reports errors by calling an error function that must not return; we longjmp back
// to the setjmp in the calling function. Only plain data lives in this struct, and the
// functions that setjmp keep no C++ objects alive across it.
struct PngContext {
  std::jmp_buf jump;
  char message[256] = {};
  // Reading: the payload and how far libpng has consumed it.
  const uint8_t* input = nullptr;
  size_t input_bytes = 0;
  size_t input_pos = 0;
  // Writing: the growing output.
  std::vector<uint8_t>* output = nullptr;
};

[[noreturn]] inline void onPngError(png_structp png, png_const_charp message) {
  auto* context = static_cast<PngContext*>(png_get_error_ptr(png));
  std::snprintf(context->message, sizeof(context->message), "%s", message);
  std::longjmp(context->jump, 1);
}

// Warnings (an ancillary chunk with a bad CRC, say) do not stop decoding and must not print.
inline void onPngWarning(png_structp, png_const_charp) {}

}  // namespace tessera::detail::png
