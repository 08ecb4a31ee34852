#pragma once
/// \file
/// Pictures and images as PNG and TIFF files, written so that a failed write leaves no file
/// behind.

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

/// The same for an image of 1 to 4 channels (gray, gray+alpha, RGB, RGBA): an 8-bit PNG for
/// u8 samples, a 16-bit PNG for u16; f32 images fail with kUnsupported (use writeTiff).
[[nodiscard]] Result<void> writePng(const Image& image, const std::string& path);

/// Writes an image of any sample type as an uncompressed baseline TIFF (8/16-bit unsigned or
/// 32-bit IEEE float samples, min-is-black or RGB, alpha as an unassociated extra sample),
/// atomically as writePng. kTooLarge past 4 GiB of texels.
[[nodiscard]] Result<void> writeTiff(const Image& image, const std::string& path);

}  // namespace tessera
