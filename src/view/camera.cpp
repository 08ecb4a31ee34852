// The camera of every view: its basis, its pixel angle, the ray through a screen point and
// the projection a GPU draws with (docs/rendering.md, "Screen and texture coordinates").
#include <tessera/view.h>

#include <algorithm>
#include <cmath>

namespace tessera {

double texelsPerPixelOf(const OrthoView& view) {
  return view.texels_per_pixel > 0 ? view.texels_per_pixel : 1;
}

CameraBasis cameraBasis(const PerspectiveView& view) {
  CameraBasis b;
  b.forward = {std::sin(view.yaw_rad) * std::cos(view.pitch_rad),
               -std::cos(view.yaw_rad) * std::cos(view.pitch_rad), std::sin(view.pitch_rad)};
  b.right = {std::cos(view.yaw_rad), std::sin(view.yaw_rad), 0};
  const Vec3& f = b.forward;
  const Vec3& r = b.right;
  b.up = {f.y * r.z - f.z * r.y, f.z * r.x - f.x * r.z, f.x * r.y - f.y * r.x};
  if (view.roll_rad != 0) {
    const double c = std::cos(view.roll_rad), s = std::sin(view.roll_rad);
    const Vec3 right = b.right, up = b.up;
    b.right = {right.x * c + up.x * s, right.y * c + up.y * s, right.z * c + up.z * s};
    b.up = {up.x * c - right.x * s, up.y * c - right.y * s, up.z * c - right.z * s};
  }
  return b;
}

double pixelAngle(const PerspectiveView& view) {
  return 2 * std::tan(view.fov_y_rad / 2) / std::max(1u, view.viewport_h);
}

Vec3 rayDirection(const PerspectiveView& view, double ndc_x, double ndc_y) {
  const CameraBasis b = cameraBasis(view);
  const double tan_half = std::tan(view.fov_y_rad / 2);
  const double aspect = double(std::max(1u, view.viewport_w)) / std::max(1u, view.viewport_h);
  return {b.forward.x + (b.right.x * ndc_x * aspect + b.up.x * ndc_y) * tan_half,
          b.forward.y + (b.right.y * ndc_x * aspect + b.up.y * ndc_y) * tan_half,
          b.forward.z + (b.right.z * ndc_x * aspect + b.up.z * ndc_y) * tan_half};
}

namespace {

ViewProjection orthoProjection(const OrthoView& o) {
  ViewProjection t;
  float* m = t.matrix;
  const double w = std::max(1u, o.viewport_w), h = std::max(1u, o.viewport_h);
  t.anchor_x = o.centre_x;
  t.anchor_y = o.centre_y;
  // Inverse of textureAt: d = R^T (uv - c) / tpp, then screen y down -> NDC y up.
  const double tpp = texelsPerPixelOf(o);
  const double c = std::cos(o.rotation_rad), s = std::sin(o.rotation_rad);
  const double kx = 2 / (w * tpp), ky = -2 / (h * tpp);
  m[0] = float(kx * c);   // x_ndc from u
  m[1] = float(ky * -s);  // y_ndc from u
  m[4] = float(kx * s);   // x_ndc from v
  m[5] = float(ky * c);   // y_ndc from v
  m[10] = 1;
  m[15] = 1;
  return t;
}

ViewProjection perspectiveProjection(const PerspectiveView& p, const ImageInfo& info) {
  ViewProjection t;
  float* m = t.matrix;
  const double w = std::max(1u, p.viewport_w), h = std::max(1u, p.viewport_h);
  t.anchor_x = p.eye_x;
  t.anchor_y = p.eye_y;
  const CameraBasis basis = cameraBasis(p);
  const double tan_half = std::tan(p.fov_y_rad / 2);
  const double aspect = w / h;
  const double eye_z = std::max(p.eye_z, 1e-6);
  const double pixel_angle = 2 * tan_half / h;
  const double far_distance =
      std::ldexp(double(info.tile_size_px), int(info.level_count)) / pixel_angle + eye_z;
  const double near_distance = std::min(eye_z * 0.5, far_distance * 1e-6);
  // Camera coordinates of ground point (x, y, 0) relative to the eye's ground point:
  // q = (x, y, -eye_z); x_c = r.q, y_c = u.q, z_c = f.q (depth along the view). Each row is
  // (a_x, a_y, -a_z eye_z), its last term applied through w = 1.
  auto row = [&](const Vec3& axis, double* out) {
    out[0] = axis.x;
    out[1] = axis.y;
    out[2] = -axis.z * eye_z;
  };
  double r[3], u[3], f[3];
  row(basis.right, r);
  row(basis.up, u);
  row(basis.forward, f);
  const double a = (far_distance + near_distance) / (far_distance - near_distance);
  const double b = -2 * far_distance * near_distance / (far_distance - near_distance);
  // clip = (x_c / (tan_half * aspect), y_c / tan_half, a * z_c + b, z_c)
  const double sx = 1 / (tan_half * aspect), sy = 1 / tan_half;
  m[0] = float(r[0] * sx);
  m[4] = float(r[1] * sx);
  m[12] = float(r[2] * sx);
  m[1] = float(u[0] * sy);
  m[5] = float(u[1] * sy);
  m[13] = float(u[2] * sy);
  m[2] = float(f[0] * a);
  m[6] = float(f[1] * a);
  m[14] = float(f[2] * a + b);
  m[3] = float(f[0]);
  m[7] = float(f[1]);
  m[15] = float(f[2]);
  return t;
}

}  // namespace

ViewProjection viewProjection(const View& view, const ImageInfo& info) {
  return view.kind == View::Kind::kOrtho ? orthoProjection(view.ortho)
                                         : perspectiveProjection(view.perspective, info);
}

}  // namespace tessera
