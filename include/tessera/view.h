#pragma once
/// \file
/// A view of an image and the camera that maps it to the screen, for every module: the
/// streamer's footprint, the CPU reference renderer, the GPU backends and the tools all take
/// their camera from here, so that a pixel sees the same texel in each of them
/// (docs/rendering.md, "Screen and texture coordinates").
///
/// Frame: texture coordinates (u, v) are level-0 texels of the image, x right and y down the
/// image; a perspective camera lives above the plane z = 0 with z up. Screen points are in
/// pixels, (0, 0) the top-left corner, pixel (px, py) sampled at (px + 0.5, py + 0.5).
/// Every function here is pure arithmetic: thread-safe, no allocation.

#include <cstdint>

#include <tessera/format.h>

namespace tessera {

/// Orthographic 2D view. Positions are level-0 pixels of the image; y grows downwards.
struct OrthoView {
  double centre_x = 0;
  double centre_y = 0;
  double texels_per_pixel = 1;  ///< level-0 texels per screen pixel (zoom); > 0
  uint32_t viewport_w = 1280;
  uint32_t viewport_h = 720;
  double rotation_rad = 0;  ///< screen rotation about the centre; positive turns x towards y
};

/// Perspective camera over the texture plane (terrain), in level-0 pixel units: the plane is
/// z = 0, x right, y down the image; `eye_z` is the height above it.
struct PerspectiveView {
  double eye_x = 0;
  double eye_y = 0;
  double eye_z = 1000;
  double yaw_rad = 0;       ///< heading: 0 looks towards -y (up the image)
  double pitch_rad = -0.7;  ///< below 0 looks down; -pi/2 straight down
  double fov_y_rad = 1.0;   ///< vertical field of view
  uint32_t viewport_w = 1280;
  uint32_t viewport_h = 720;
  /// Turns the screen about the view axis, positive from right towards up. The terrain views
  /// keep 0; a scene whose world is y-up needs it to keep its up on the screen's up. Last, so
  /// that brace initialisers of the fields above keep their meaning.
  double roll_rad = 0;
};

/// A view of one image of an archive: `ortho` or `perspective`, as `kind` says (the other
/// member is ignored).
struct View {
  enum class Kind { kOrtho, kPerspective };
  Kind kind = Kind::kOrtho;
  uint32_t image = 0;  ///< index into Archive::images()
  OrthoView ortho;
  PerspectiveView perspective;
  uint32_t viewportWidth() const {
    return kind == Kind::kOrtho ? ortho.viewport_w : perspective.viewport_w;
  }
  uint32_t viewportHeight() const {
    return kind == Kind::kOrtho ? ortho.viewport_h : perspective.viewport_h;
  }
};

/// The zoom an orthographic view is drawn at: `texels_per_pixel`, read as 1 when it is not
/// above 0 (or NaN), by the streamer and every renderer alike.
double texelsPerPixelOf(const OrthoView& view);

/// A vector in the frame of the texture plane (x right, y down the image, z up).
struct Vec3 {
  double x = 0;
  double y = 0;
  double z = 0;
};

/// The frame of a perspective camera, unit vectors.
struct CameraBasis {
  /// (sin(yaw) cos(pitch), -cos(yaw) cos(pitch), sin(pitch)): yaw 0 looks up the image.
  Vec3 forward;
  Vec3 right;  ///< (cos(yaw), sin(yaw), 0) at roll 0: screen x; roll turns it towards up
  /// forward x right: screen y towards the top row, so a camera that looks down has the
  /// horizon at the top of the screen (docs/rendering.md explains the handedness).
  Vec3 up;
};

/// The camera frame of `view` (docs/rendering.md, "Perspective").
CameraBasis cameraBasis(const PerspectiveView& view);

/// Radians one screen pixel spans at unit distance along the view: 2 tan(fov_y / 2) / h, a
/// zero viewport height read as 1. Looking straight down from height z, a pixel covers
/// z * pixelAngle level-0 texels.
double pixelAngle(const PerspectiveView& view);

/// Direction of the ray through a normalised screen point, not normalised: forward +
/// (right * ndc_x * aspect + up * ndc_y) * tan(fov_y / 2), with ndc_x from -1 (left edge) to
/// +1 (right edge), ndc_y from -1 (bottom) to +1 (top) and aspect = w / h.
Vec3 rayDirection(const PerspectiveView& view, double ndc_x, double ndc_y);

/// Level-0 texel coordinate (u, v) seen at screen point (sx, sy). Orthographic: the view
/// centre at the screen centre, `texelsPerPixelOf` texels per pixel, the screen rotated by
/// rotation_rad. Perspective: the ray through that point (`rayDirection`) hits the plane
/// z = 0; false when it does not (at or above the horizon, or an eye at or below the plane),
/// and (u, v) is then (0, 0).
bool textureAt(const View& view, double sx, double sy, double& u, double& v);

/// Level of detail at the centre of pixel (px, py): log2 of level-0 texels per pixel, rho as
/// OpenGL defines it (the longer of the two screen-axis derivatives of (u, v)). Orthographic
/// views give log2(texelsPerPixelOf) everywhere. Perspective: the analytic derivatives of the
/// ray-plane hit at the pixel centre; +infinity where the ray misses the plane.
double levelOfDetailAt(const View& view, uint32_t px, uint32_t py);

/// The inverse of `textureAt` as a GPU draws it: level-0 texel coordinates, taken relative to
/// an anchor so that 32-bit floats keep sub-texel precision on images of any size, to clip
/// space (OpenGL conventions: x and y from -1 to +1 with +1 at the top, w the depth along the
/// view for a perspective camera). A texel that `textureAt` finds at screen point (sx, sy)
/// lands on that point.
struct ViewProjection {
  double anchor_x = 0;  ///< the ortho view's centre, or the point under the eye
  double anchor_y = 0;
  float matrix[16] = {};  ///< column-major, applied to (u - anchor_x, v - anchor_y, 0, 1)
};

/// The projection of `view` over image `info`. Perspective depth only clips (renderers draw
/// the plane without a depth test): near and far bracket every ground point the view can
/// show, far where one pixel spans a whole coarsest-level tile.
ViewProjection viewProjection(const View& view, const ImageInfo& info);

}  // namespace tessera
