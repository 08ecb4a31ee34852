#pragma once
// Screenshots of `tessera view`. Kept behind one function so the viewer can switch to the
// shared PNG writer when that lands, without touching the frame loop.

#include <string>

#include <tessera/render.h>
#include <tessera/result.h>

namespace tessera::cli {

/// Writes `picture` (RGBA rows top to bottom) as a PNG at `path`, atomically (a temporary
/// renamed into place). Errors name the path.
[[nodiscard]] Result<void> writeScreenshot(const Picture& picture, const std::string& path);

/// `dir`/tessera-screenshot-<n>.png with the smallest n >= 1 not taken yet.
std::string nextScreenshotPath(const std::string& dir);

}  // namespace tessera::cli
