#pragma once
/// \file
/// Pictures and images as PNG files, written so that a failed write leaves no file behind.

#include <string>

#include <tessera/format.h>
#include <tessera/render.h>
#include <tessera/result.h>

namespace tessera {

/// Writes a picture as an 8-bit RGBA PNG. Written to a temporary beside `path` and renamed
/// over it when complete, so a failed write leaves no half-written file. Fails naming the path
/// (kInvalidArgument for a picture whose bytes do not match its size, kIo for the file).
/// Thread-safe.
[[nodiscard]] Result<void> writePng(const Picture& picture, const std::string& path);

/// The same for an image of 1 to 4 channels (gray, gray+alpha, RGB, RGBA).
[[nodiscard]] Result<void> writePng(const Image& image, const std::string& path);

}  // namespace tessera
