#include "view_camera.h"

#include <algorithm>
#include <cmath>

namespace tessera::cli {

namespace {

constexpr double kPi = 3.14159265358979323846;
// Below this pitch the horizon is in the picture but the ground still fills its lower part;
// -pi/2 looks straight down (a small step off, so the heading stays defined).
constexpr double kHighestPitchRad = -0.08;
constexpr double kLowestPitchRad = -kPi / 2 + 0.01;

double longerSide(const ImageInfo& info) {
  return double(std::max(info.width_px, info.height_px));
}

struct Basis {
  double f[3], r[3], u[3];
};

// The camera basis of gl::viewTransform (and the runtime's residency): forward, right, r x f.
Basis basisOf(const PerspectiveView& p) {
  Basis b;
  b.f[0] = std::sin(p.yaw_rad) * std::cos(p.pitch_rad);
  b.f[1] = -std::cos(p.yaw_rad) * std::cos(p.pitch_rad);
  b.f[2] = std::sin(p.pitch_rad);
  b.r[0] = std::cos(p.yaw_rad);
  b.r[1] = std::sin(p.yaw_rad);
  b.r[2] = 0;
  b.u[0] = b.r[1] * b.f[2] - b.r[2] * b.f[1];
  b.u[1] = b.r[2] * b.f[0] - b.r[0] * b.f[2];
  b.u[2] = b.r[0] * b.f[1] - b.r[1] * b.f[0];
  return b;
}

// Radians one screen pixel spans at the centre of a perspective view.
double pixelAngle(double fov_y_rad, uint32_t viewport_h) {
  return 2 * std::tan(fov_y_rad / 2) / std::max(1u, viewport_h);
}

}  // namespace

std::optional<PlanePoint> planeAt(const View& view, double sx, double sy) {
  if (view.kind == View::Kind::kOrtho) {
    const OrthoView& o = view.ortho;
    // Inverse of the renderers' d = R^T (uv - c) / tpp.
    const double dx = sx - o.viewport_w / 2.0, dy = sy - o.viewport_h / 2.0;
    const double c = std::cos(o.rotation_rad), s = std::sin(o.rotation_rad);
    return PlanePoint{o.centre_x + (c * dx - s * dy) * o.texels_per_pixel,
                      o.centre_y + (s * dx + c * dy) * o.texels_per_pixel};
  }
  const PerspectiveView& p = view.perspective;
  const Basis b = basisOf(p);
  const double w = std::max(1u, p.viewport_w), h = std::max(1u, p.viewport_h);
  const double tan_half = std::tan(p.fov_y_rad / 2);
  // The shared basis's u = r x f points down the screen (towards the ground at the bottom).
  const double nx = (2 * sx / w - 1) * tan_half * (w / h), ny = (2 * sy / h - 1) * tan_half;
  double dir[3];
  for (int i = 0; i < 3; ++i) dir[i] = b.f[i] + b.r[i] * nx + b.u[i] * ny;
  if (dir[2] >= 0) return std::nullopt;
  const double t = p.eye_z / -dir[2];
  return PlanePoint{p.eye_x + t * dir[0], p.eye_y + t * dir[1]};
}

double minTexelsPerPixel() {
  return 1.0 / 64;
}

double maxTexelsPerPixel(const ImageInfo& info, uint32_t viewport_w, uint32_t viewport_h) {
  const double shorter = std::max(1u, std::min(viewport_w, viewport_h));
  return std::max(1.0, 16 * longerSide(info) / shorter);
}

OrthoView fitImage(const ImageInfo& info, uint32_t viewport_w, uint32_t viewport_h) {
  OrthoView view;
  view.viewport_w = std::max(1u, viewport_w);
  view.viewport_h = std::max(1u, viewport_h);
  view.centre_x = info.width_px / 2.0;
  view.centre_y = info.height_px / 2.0;
  constexpr double kMargin = 1.05;
  view.texels_per_pixel = kMargin * std::max(double(info.width_px) / view.viewport_w,
                                             double(info.height_px) / view.viewport_h);
  return view;
}

void panByScreen(OrthoView& view, double dx_px, double dy_px) {
  const double c = std::cos(view.rotation_rad), s = std::sin(view.rotation_rad);
  view.centre_x -= (c * dx_px - s * dy_px) * view.texels_per_pixel;
  view.centre_y -= (s * dx_px + c * dy_px) * view.texels_per_pixel;
}

void zoomAround(OrthoView& view, const ImageInfo& info, double factor, double sx, double sy) {
  View before;
  before.ortho = view;
  const std::optional<PlanePoint> anchor = planeAt(before, sx, sy);
  view.texels_per_pixel = std::clamp(view.texels_per_pixel * factor, minTexelsPerPixel(),
                                     maxTexelsPerPixel(info, view.viewport_w, view.viewport_h));
  // Put the anchor back under the cursor: the centre is the anchor minus the cursor's offset
  // at the new zoom.
  View after;
  after.ortho = view;
  const std::optional<PlanePoint> moved = planeAt(after, sx, sy);
  view.centre_x += anchor->x - moved->x;
  view.centre_y += anchor->y - moved->y;
}

void clampToImage(OrthoView& view, const ImageInfo& info) {
  view.centre_x = std::clamp(view.centre_x, 0.0, double(info.width_px));
  view.centre_y = std::clamp(view.centre_y, 0.0, double(info.height_px));
}

double minAltitude() {
  return 2;
}

double maxAltitude(const ImageInfo& info) {
  return 4 * longerSide(info);
}

PerspectiveView perspectiveFrom(const OrthoView& ortho, const ImageInfo& info, double pitch_rad) {
  PerspectiveView view;
  view.viewport_w = ortho.viewport_w;
  view.viewport_h = ortho.viewport_h;
  view.yaw_rad = ortho.rotation_rad;
  view.pitch_rad = std::clamp(pitch_rad, kLowestPitchRad, kHighestPitchRad);
  // Across the view direction a pixel at distance D spans D * pixel_angle texels.
  const double distance = ortho.texels_per_pixel / pixelAngle(view.fov_y_rad, view.viewport_h);
  view.eye_z = std::clamp(distance * std::sin(-view.pitch_rad), minAltitude(), maxAltitude(info));
  const double back = view.eye_z / std::tan(-view.pitch_rad);
  view.eye_x = ortho.centre_x - std::sin(view.yaw_rad) * back;
  view.eye_y = ortho.centre_y + std::cos(view.yaw_rad) * back;
  return view;
}

OrthoView orthoFrom(const PerspectiveView& view, const ImageInfo& info) {
  View v;
  v.kind = View::Kind::kPerspective;
  v.perspective = view;
  const std::optional<PlanePoint> seen = planeAt(v, view.viewport_w / 2.0, view.viewport_h / 2.0);
  const PlanePoint centre = seen.value_or(PlanePoint{view.eye_x, view.eye_y});
  const double dx = centre.x - view.eye_x, dy = centre.y - view.eye_y;
  const double distance = std::sqrt(dx * dx + dy * dy + view.eye_z * view.eye_z);
  OrthoView ortho;
  ortho.viewport_w = view.viewport_w;
  ortho.viewport_h = view.viewport_h;
  ortho.centre_x = centre.x;
  ortho.centre_y = centre.y;
  ortho.texels_per_pixel =
      std::clamp(distance * pixelAngle(view.fov_y_rad, view.viewport_h), minTexelsPerPixel(),
                 maxTexelsPerPixel(info, view.viewport_w, view.viewport_h));
  clampToImage(ortho, info);
  return ortho;
}

void flyMove(PerspectiveView& view, const ImageInfo& info, double forward, double right) {
  const double heading_x = std::sin(view.yaw_rad), heading_y = -std::cos(view.yaw_rad);
  view.eye_x += (heading_x * forward - heading_y * right) * view.eye_z;
  view.eye_y += (heading_y * forward + heading_x * right) * view.eye_z;
  // The eye may leave the image by one image size, enough to look back at it from outside.
  const double w = info.width_px, h = info.height_px;
  view.eye_x = std::clamp(view.eye_x, -w, 2 * w);
  view.eye_y = std::clamp(view.eye_y, -h, 2 * h);
}

void flyTurn(PerspectiveView& view, double dx_px, double dy_px) {
  constexpr double kRadPerPixel = 0.004;
  view.yaw_rad = std::remainder(view.yaw_rad + dx_px * kRadPerPixel, 2 * kPi);
  view.pitch_rad =
      std::clamp(view.pitch_rad - dy_px * kRadPerPixel, kLowestPitchRad, kHighestPitchRad);
}

void flyClimb(PerspectiveView& view, const ImageInfo& info, double factor) {
  view.eye_z = std::clamp(view.eye_z * factor, minAltitude(), maxAltitude(info));
}

}  // namespace tessera::cli
