// The screen-to-texture half of the camera (docs/rendering.md, "Screen and texture
// coordinates" and "Level of detail").
#include "view/screen_mapping.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace tessera::detail {

namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();

}  // namespace

ScreenMapping::ScreenMapping(const View& view) {
  if (view.kind == View::Kind::kOrtho) {
    const OrthoView& o = view.ortho;
    const double tpp = texelsPerPixelOf(o);
    const double c = std::cos(o.rotation_rad), s = std::sin(o.rotation_rad);
    // u = cx + tpp (c dx - s dy), v = cy + tpp (s dx + c dy), (dx, dy) = (sx - w/2, sy - h/2).
    a_x_ = tpp * c;
    a_y_ = -tpp * s;
    b_x_ = tpp * s;
    b_y_ = tpp * c;
    const double hw = o.viewport_w * 0.5, hh = o.viewport_h * 0.5;
    u0_ = o.centre_x - a_x_ * hw - a_y_ * hh;
    v0_ = o.centre_y - b_x_ * hw - b_y_ * hh;
    ortho_lambda_ = std::log2(tpp);
    return;
  }
  ortho_ = false;
  const PerspectiveView& p = view.perspective;
  const CameraBasis basis = cameraBasis(p);
  const double f[3] = {basis.forward.x, basis.forward.y, basis.forward.z};
  const double r[3] = {basis.right.x, basis.right.y, basis.right.z};
  const double up[3] = {basis.up.x, basis.up.y, basis.up.z};
  const double w = std::max(1u, p.viewport_w), h = std::max(1u, p.viewport_h);
  const double aspect = w / h;
  const double tan_half = std::tan(p.fov_y_rad / 2);
  // rayDirection with ndc_x = 2 sx / w - 1 and ndc_y = 1 - 2 sy / h, written as linear in
  // (sx, sy). Both steps are pixelAngle long.
  for (int i = 0; i < 3; ++i) {
    c_[i] = f[i] + (-r[i] * aspect + up[i]) * tan_half;
    dx_[i] = r[i] * aspect * tan_half * 2 / w;
    dy_[i] = -up[i] * tan_half * 2 / h;
  }
  eye_x_ = p.eye_x;
  eye_y_ = p.eye_y;
  eye_z_ = p.eye_z;
}

bool ScreenMapping::map(double sx, double sy, TexelPoint& out) const {
  if (ortho_) {
    out.u = u0_ + a_x_ * sx + a_y_ * sy;
    out.v = v0_ + b_x_ * sx + b_y_ * sy;
    out.lambda = ortho_lambda_;
    return true;
  }
  const double d0 = c_[0] + dx_[0] * sx + dy_[0] * sy;
  const double d1 = c_[1] + dx_[1] * sx + dy_[1] * sy;
  const double d2 = c_[2] + dx_[2] * sx + dy_[2] * sy;
  if (!(eye_z_ > 0) || !(d2 < 0)) {
    out = {0, 0, kInfinity};
    return false;
  }
  // Hit of eye + t d with z = 0: t = eye_z / -d2, so u = eye_x - eye_z d0 / d2. Its exact
  // derivative along a screen axis with direction step e is -eye_z (e0 d2 - d0 e2) / d2^2.
  const double t = eye_z_ / -d2;
  out.u = eye_x_ + t * d0;
  out.v = eye_y_ + t * d1;
  const double k = -eye_z_ / (d2 * d2);
  const double du_dx = k * (dx_[0] * d2 - d0 * dx_[2]);
  const double dv_dx = k * (dx_[1] * d2 - d1 * dx_[2]);
  const double du_dy = k * (dy_[0] * d2 - d0 * dy_[2]);
  const double dv_dy = k * (dy_[1] * d2 - d1 * dy_[2]);
  // rho = max(|d(u,v)/dx|, |d(u,v)/dy|) (OpenGL 4.6, eq. 8.7); Luo & Duan, eq. 2.
  const double rho2 = std::max(du_dx * du_dx + dv_dx * dv_dx, du_dy * du_dy + dv_dy * dv_dy);
  out.lambda = 0.5 * std::log2(rho2);
  return true;
}

}  // namespace tessera::detail

namespace tessera {

bool textureAt(const View& view, double sx, double sy, double& u, double& v) {
  detail::TexelPoint point;
  const bool hit = detail::ScreenMapping(view).map(sx, sy, point);
  u = point.u;
  v = point.v;
  return hit;
}

double levelOfDetailAt(const View& view, uint32_t px, uint32_t py) {
  detail::TexelPoint point;
  detail::ScreenMapping(view).map(px + 0.5, py + 0.5, point);
  return point.lambda;
}

}  // namespace tessera
