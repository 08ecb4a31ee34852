#pragma once
// Camera paths for `tessera fly`: built-in paths (pan, zoom, jump, spiral) and keyframe files
// (docs/fly.md), evaluated at any time.

#include <string>
#include <vector>

#include <tessera/format.h>
#include <tessera/result.h>
#include <tessera/stream.h>

namespace tessera::cli {

/// One keyframe: at `t_s`, the view is centred on (x, y) level-0 pixels at `texels_per_pixel`.
/// `jump` marks a teleport: no interpolation from the previous keyframe.
struct Keyframe {
  double t_s = 0;
  double x = 0;
  double y = 0;
  double texels_per_pixel = 1;
  double rotation_rad = 0;
  bool jump = false;
};

struct CameraPath {
  std::string name;
  std::vector<Keyframe> keys;  ///< sorted by time
  double durationS() const { return keys.empty() ? 0 : keys.back().t_s; }
  /// The view at time `t_s` (clamped to the path), for a viewport.
  OrthoView at(double t_s, uint32_t viewport_w, uint32_t viewport_h) const;
  /// True when a jump keyframe lies in (t0, t1].
  bool jumpsBetween(double t0, double t1) const;
};

/// Builds a named path over an image: "pan" (left to right through the middle at `speed`
/// level-0 px/s, full detail), "zoom" (from the whole image in to full detail and out),
/// "jump" (teleports to 5 spread positions, 2 s each), "spiral" (outwards at `speed`).
Result<CameraPath> builtinPath(const std::string& name, const ImageInfo& image, double speed_px_s,
                               double duration_s, uint32_t viewport_w, uint32_t viewport_h);
/// Reads a keyframe file (docs/fly.md): one keyframe per line "t x y tpp [rotation] [jump]",
/// '#' comments. Errors name the file and line.
Result<CameraPath> loadPathFile(const std::string& path);

}  // namespace tessera::cli
