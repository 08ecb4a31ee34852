#pragma once
// The web viewer's files (web/viewer/), embedded into the binary at build time by
// cmake/EmbedFiles.cmake; the generated viewer_assets.cpp defines viewerAssets().

#include <cstddef>
#include <span>
#include <string_view>

namespace tessera::detail {

struct EmbeddedFile {
  std::string_view path;  ///< relative to web/viewer/, '/'-separated, e.g. "index.html"
  std::string_view bytes;
};

/// Every embedded file, sorted by path. Static storage; thread-safe.
std::span<const EmbeddedFile> viewerAssets();

}  // namespace tessera::detail
