#include "scene_lod.h"

#include <algorithm>
#include <cmath>

namespace tessera::detail {
namespace {

Vec3 combine(const Vec3& a, double sa, const Vec3& b, double sb) {
  return {a.x * sa + b.x * sb, a.y * sa + b.y * sb, a.z * sa + b.z * sb};
}

}  // namespace

double longestSide(const Box3& box) {
  return std::max({double(box.max[0]) - box.min[0], double(box.max[1]) - box.min[1],
                   double(box.max[2]) - box.min[2]});
}

Frustum frustumOf(const PerspectiveView& camera) {
  const CameraBasis basis = cameraBasis(camera);
  const double tan_half = std::tan(camera.fov_y_rad / 2);
  const double aspect =
      camera.viewport_h == 0 ? 1.0 : double(camera.viewport_w) / camera.viewport_h;
  Frustum frustum;
  frustum.eye = {camera.eye_x, camera.eye_y, camera.eye_z};
  // A side plane through the eye holds the forward axis tilted by the half field of view:
  // its outward normal is the side axis minus forward times the tangent.
  frustum.normal[0] = combine(basis.right, -1, basis.forward, -aspect * tan_half);
  frustum.normal[1] = combine(basis.right, 1, basis.forward, -aspect * tan_half);
  frustum.normal[2] = combine(basis.up, -1, basis.forward, -tan_half);
  frustum.normal[3] = combine(basis.up, 1, basis.forward, -tan_half);
  frustum.normal[4] = combine(basis.forward, -1, basis.forward, 0);
  return frustum;
}

bool boxMayBeVisible(const Frustum& frustum, const Box3& box) {
  for (const Vec3& n : frustum.normal) {
    // The box corner furthest inside this plane: outside when even it is outside.
    const double x = (n.x > 0 ? box.min[0] : box.max[0]) - frustum.eye.x;
    const double y = (n.y > 0 ? box.min[1] : box.max[1]) - frustum.eye.y;
    const double z = (n.z > 0 ? box.min[2] : box.max[2]) - frustum.eye.z;
    if (n.x * x + n.y * y + n.z * z > 0) return false;
  }
  return true;
}

bool boxInside(const Frustum& frustum, const Box3& box) {
  for (const Vec3& n : frustum.normal) {
    // The corner furthest outside this plane: inside when even it is inside.
    const double x = (n.x > 0 ? box.max[0] : box.min[0]) - frustum.eye.x;
    const double y = (n.y > 0 ? box.max[1] : box.min[1]) - frustum.eye.y;
    const double z = (n.z > 0 ? box.max[2] : box.min[2]) - frustum.eye.z;
    if (n.x * x + n.y * y + n.z * z > 0) return false;
  }
  return true;
}

double distanceToBox(const PerspectiveView& camera, const Box3& box) {
  const double eye[3] = {camera.eye_x, camera.eye_y, camera.eye_z};
  double sum = 0;
  for (int a = 0; a < 3; ++a) {
    const double outside = std::max({0.0, box.min[a] - eye[a], eye[a] - box.max[a]});
    sum += outside * outside;
  }
  return std::sqrt(sum);
}

LodFrame lodFrame(const PerspectiveView& camera, double lod_bias) {
  LodFrame frame;
  frame.camera = camera;
  frame.pixel_angle = pixelAngle(camera);
  frame.viewport_px = double(camera.viewport_w) * camera.viewport_h;
  frame.bias_scale = std::exp2(lod_bias);
  return frame;
}

ObjectScale objectScale(const LodFrame& frame, const Box3& bounds) {
  ObjectScale scale;
  const double side = longestSide(bounds);
  if (!(side > 0)) return scale;
  const double distance = distanceToBox(frame.camera, bounds);
  if (distance <= 0) {
    scale.eye_inside = true;
    scale.pixels = uint64_t(frame.viewport_px);
    return scale;
  }
  scale.pixels_across = side / (distance * frame.pixel_angle);
  scale.pixels = uint64_t(std::min(frame.viewport_px, scale.pixels_across * scale.pixels_across));
  return scale;
}

uint32_t levelFor(const LodFrame& frame, const ObjectScale& scale, const ImageInfo& texture) {
  const uint32_t coarsest = texture.level_count == 0 ? 0 : texture.level_count - 1;
  if (!scale.eye_inside && !(scale.pixels_across > 0)) return coarsest;
  // rho = 1 inside the box: the finest level (no finer than the bias allows).
  const double rho = scale.eye_inside ? 1.0
                                      : double(std::max(texture.width_px, texture.height_px)) /
                                            scale.pixels_across;
  // floor(log2(rho) + bias) as the binary exponent of rho * 2^bias (ilogb is exact floor).
  const double scaled = rho * frame.bias_scale;
  if (!(scaled >= 1)) return 0;
  if (!std::isfinite(scaled)) return coarsest;
  return std::min<uint32_t>(coarsest, uint32_t(std::ilogb(scaled)));
}

ObjectLod objectLod(const LodFrame& frame, const Box3& bounds, const ImageInfo& texture) {
  const ObjectScale scale = objectScale(frame, bounds);
  return {levelFor(frame, scale, texture), scale.pixels};
}

ObjectLod objectLod(const PerspectiveView& camera, const Box3& bounds, const ImageInfo& texture,
                    double lod_bias) {
  return objectLod(lodFrame(camera, lod_bias), bounds, texture);
}

}  // namespace tessera::detail
