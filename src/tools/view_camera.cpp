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

}  // namespace

std::optional<PlanePoint> planeAt(const View& view, double sx, double sy) {
  PlanePoint point;
  if (!textureAt(view, sx, sy, point.x, point.y)) return std::nullopt;
  return point;
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
  const double distance = ortho.texels_per_pixel / pixelAngle(view);
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
  ortho.texels_per_pixel = std::clamp(distance * pixelAngle(view), minTexelsPerPixel(),
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
