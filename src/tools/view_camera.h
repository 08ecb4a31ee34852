#pragma once
// The camera of `tessera view`: how mouse and keys move an orthographic or perspective view of
// an image. Plain math on tessera::View, no window or GL, so tests need no display.

#include <optional>

#include <tessera/format.h>
#include <tessera/view.h>

namespace tessera::cli {

/// A point on the texture plane, level-0 pixels (y down).
struct PlanePoint {
  double x = 0;
  double y = 0;
};

/// The plane point seen at screen position (sx, sy) (pixels, (0, 0) the top-left corner):
/// tessera::textureAt, the camera every renderer draws with. Empty for a perspective ray at or
/// above the horizon.
std::optional<PlanePoint> planeAt(const View& view, double sx, double sy);

/// Zoom limits: at most 64 screen pixels per texel in, and out until the whole image spans
/// a sixteenth of the shorter screen side.
double minTexelsPerPixel();
double maxTexelsPerPixel(const ImageInfo& info, uint32_t viewport_w, uint32_t viewport_h);

/// The whole image centred in the viewport with a small margin (the Home key).
OrthoView fitImage(const ImageInfo& info, uint32_t viewport_w, uint32_t viewport_h);

/// Moves the view so that the texture follows a drag of (dx, dy) screen pixels.
void panByScreen(OrthoView& view, double dx_px, double dy_px);

/// Multiplies texels per pixel by `factor` (< 1 zooms in), keeping the texel under (sx, sy)
/// under it; the result is clamped to the zoom limits.
void zoomAround(OrthoView& view, const ImageInfo& info, double factor, double sx, double sy);

/// Keeps the view centre on the image, so the picture can never be lost off screen.
void clampToImage(OrthoView& view, const ImageInfo& info);

/// Lowest and highest eye altitude of the fly-over, level-0 pixels.
double minAltitude();
double maxAltitude(const ImageInfo& info);

/// A perspective camera that sees about what `ortho` shows: the eye behind and above its
/// centre, looking at it at `pitch_rad`, at the altitude where the centre's texel density
/// matches.
PerspectiveView perspectiveFrom(const OrthoView& ortho, const ImageInfo& info, double pitch_rad);

/// The orthographic view of what the perspective camera looks at: centred on the ground point
/// at the screen centre (or under the eye at the horizon), at that point's texel density.
OrthoView orthoFrom(const PerspectiveView& view, const ImageInfo& info);

/// Fly-over moves, in units of the altitude so the speed looks the same at every height:
/// `forward` and `right` in altitudes (negative goes back or left), along the heading.
void flyMove(PerspectiveView& view, const ImageInfo& info, double forward, double right);
/// Turns the camera by a mouse drag of (dx, dy) pixels: yaw with dx, pitch with dy, pitch kept
/// between just below the horizon and straight down.
void flyTurn(PerspectiveView& view, double dx_px, double dy_px);
/// Multiplies the altitude by `factor`, clamped to [minAltitude, maxAltitude].
void flyClimb(PerspectiveView& view, const ImageInfo& info, double factor);

}  // namespace tessera::cli
