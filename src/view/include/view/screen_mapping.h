#pragma once
// A view's screen-to-texture mapping with its constants computed once, for loops over many
// pixels (the CPU reference renderer); `tessera::textureAt` and `levelOfDetailAt` are the
// one-point forms. Pure arithmetic; owned by one thread, cheap to copy.

#include <tessera/view.h>

namespace tessera::detail {

/// Where a screen point lands on the texture and how dense the texture is there.
struct TexelPoint {
  double u = 0;  ///< level-0 texel coordinate, texel i covering [i, i+1)
  double v = 0;
  double lambda = 0;  ///< log2 of level-0 texels per pixel (OpenGL's rho); +inf on a miss
};

/// A view's mapping from screen points (pixel units, (0, 0) the top-left corner) to level-0
/// texel coordinates.
class ScreenMapping {
 public:
  explicit ScreenMapping(const View& view);

  /// Maps screen point (sx, sy). False when a perspective ray misses the plane z = 0 (at or
  /// above the horizon, or an eye at or below the plane); `out` is then (0, 0, +inf).
  bool map(double sx, double sy, TexelPoint& out) const;

 private:
  bool ortho_ = true;
  // Orthographic: u = u0 + a_x * sx + a_y * sy, v = v0 + b_x * sx + b_y * sy.
  double u0_ = 0, v0_ = 0, a_x_ = 1, a_y_ = 0, b_x_ = 0, b_y_ = 1, ortho_lambda_ = 0;
  // Perspective: ray direction d = c + dx * sx + dy * sy (not normalised) from the eye.
  double eye_x_ = 0, eye_y_ = 0, eye_z_ = 1;
  double c_[3] = {0, 0, -1};
  double dx_[3] = {0, 0, 0};
  double dy_[3] = {0, 0, 0};
};

}  // namespace tessera::detail
