#include <cmath>

#include <fmt/format.h>

#include <tessera/gl.h>

#include "gl/renderers.h"

namespace tessera {

namespace gl {

ViewTransform viewTransform(const View& view, const ImageInfo& info) {
  ViewTransform t;
  float* m = t.view_projection;
  const double w = std::max(1u, view.viewportWidth()), h = std::max(1u, view.viewportHeight());
  if (view.kind == View::Kind::kOrtho) {
    const OrthoView& o = view.ortho;
    t.anchor_x = o.centre_x;
    t.anchor_y = o.centre_y;
    // Inverse of textureAt: d = R^T (uv - c) / tpp, then screen y down -> NDC y up.
    const double tpp = o.texels_per_pixel > 0 ? o.texels_per_pixel : 1;
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
  const PerspectiveView& p = view.perspective;
  t.anchor_x = p.eye_x;
  t.anchor_y = p.eye_y;
  // The camera of tessera::textureAt (docs/rendering.md): forward and right as in the runtime
  // (src/stream/residency.cpp), up = f x r, so the screen's top row looks above the centre.
  const double fx = std::sin(p.yaw_rad) * std::cos(p.pitch_rad);
  const double fy = -std::cos(p.yaw_rad) * std::cos(p.pitch_rad);
  const double fz = std::sin(p.pitch_rad);
  const double rx = std::cos(p.yaw_rad), ry = std::sin(p.yaw_rad), rz = 0;
  const double ux = fy * rz - fz * ry, uy = fz * rx - fx * rz, uz = fx * ry - fy * rx;
  const double tan_half = std::tan(p.fov_y_rad / 2);
  const double aspect = w / h;
  const double eye_z = std::max(p.eye_z, 1e-6);
  // Depth only clips: the plane is drawn without a depth test. Near and far bracket every
  // visible ground point (the far one where a pixel covers a whole coarsest tile).
  const double pixel_angle = 2 * tan_half / h;
  const double far_distance =
      std::ldexp(double(info.tile_size_px), int(info.level_count)) / pixel_angle + eye_z;
  const double near_distance = std::min(eye_z * 0.5, far_distance * 1e-6);
  // Camera coordinates of ground point (x, y, 0) relative to the eye's ground point:
  // q = (x, y, -eye_z); x_c = r.q, y_c = u.q, z_c = f.q (depth along the view).
  auto row = [&](double ax, double ay, double az, double* out) {
    out[0] = ax;
    out[1] = ay;
    out[2] = -az * eye_z;  // the constant term, applied through w = 1
  };
  double r[3], u[3], f[3];
  row(rx, ry, rz, r);
  row(ux, uy, uz, u);
  row(fx, fy, fz, f);
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

Picture TargetRenderer::readPixels() {
  Picture picture;
  picture.width = target_.width();
  picture.height = target_.height();
  target_.read(picture.rgba);
  return picture;
}

void TargetRenderer::present(uint32_t window_width, uint32_t window_height) {
  target_.blitToWindow(window_width, window_height);
}

}  // namespace gl

Result<std::unique_ptr<GlRenderer>> GlRenderer::create(RendererKind kind, const ImageInfo& info,
                                                       const GlRendererOptions& options) {
  if (info.channels < 1 || info.channels > 4 || info.tile_size_px == 0)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("renderer: image with {} channels and {} px tiles", info.channels,
                            info.tile_size_px));
  switch (kind) {
    case RendererKind::kTileQuads: return gl::createTileQuadsRenderer(info, options);
    case RendererKind::kClipmap: return gl::createClipmapRenderer(info, options);
  }
  return fail(ErrorCode::kInvalidArgument, "unknown renderer kind");
}

}  // namespace tessera
