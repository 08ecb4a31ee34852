#pragma once
// A mosaic manifest: a JSON file placing image files anywhere on a canvas, at any size
// (docs/builder.md, "Mosaic manifests"). This file parses and checks the document alone; the
// reader (mosaic_reader.h) opens the images it names.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <tessera/result.h>

namespace tessera::detail {

/// Most images one manifest may name: each is checked at open.
inline constexpr size_t kMaxMosaicImages = size_t(1) << 20;
/// Largest manifest file read (about 100 bytes an image at the image limit).
inline constexpr uint64_t kMaxManifestBytes = uint64_t(128) << 20;

/// One entry of "images", in manifest order: later entries are drawn over earlier ones.
struct MosaicImage {
  std::string path;       ///< resolved against the manifest's folder (absolute paths kept)
  std::string path_text;  ///< as written in the manifest, for messages
  uint32_t x_px = 0;      ///< left edge on the canvas, 0..kMaxImageSidePx
  uint32_t y_px = 0;      ///< top edge on the canvas, 0..kMaxImageSidePx
  /// Size the manifest states, checked against the file; 0 when not stated.
  uint32_t width_px = 0, height_px = 0;
};

/// A parsed manifest. Canvas sides of 0 mean "not stated": the reader takes the images'
/// extent. The background's length is checked against the images' channels by the reader.
struct MosaicManifest {
  std::string path;  ///< the manifest file, as given
  uint32_t width_px = 0, height_px = 0;
  std::vector<double> background;   ///< one value per channel, or empty for zeros
  std::vector<MosaicImage> images;  ///< at least one

  /// "scan.json: images[3] (b.tif)", the prefix of every message about entry `index`.
  std::string where(size_t index) const;
};

/// True when `bytes` (the start of a file) open a JSON object: '{' after optional whitespace
/// and a UTF-8 byte order mark. No image format a build reads starts so.
bool looksLikeManifest(const uint8_t* bytes, size_t size);

/// Reads and checks the manifest at `path`: the file (present, at most kMaxManifestBytes), the
/// JSON (syntax errors give line and column), and the schema: an object with "images" (1 to
/// kMaxMosaicImages entries, each {"path", "x", "y", optional "width", "height"}) and optional
/// "width", "height" and "background"; whole, non-negative pixel numbers up to
/// kMaxImageSidePx; no unknown keys (a misspelt key would otherwise be silently ignored).
/// Fails naming the manifest, the entry and the problem. Opens no image.
[[nodiscard]] Result<MosaicManifest> readMosaicManifest(const std::string& path);

}  // namespace tessera::detail
