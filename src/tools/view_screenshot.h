#pragma once
// Screenshot names of `tessera view` (the pictures are written by tessera::writePng).

#include <string>

#include <tessera/render.h>
#include <tessera/result.h>

namespace tessera::cli {

/// `dir`/tessera-screenshot-<n>.png with the smallest n >= 1 not taken yet.
std::string nextScreenshotPath(const std::string& dir);

}  // namespace tessera::cli
