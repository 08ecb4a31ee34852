#include "id_raster.h"

#include <algorithm>
#include <cmath>

#include <tessera/check.h>

namespace tessera::detail {

namespace {

struct CameraPoint {
  double x, y, z;  ///< right, up, forward (depth)
};

struct ScreenPoint {
  double x, y;       ///< pixels from the top-left corner
  double inverse_z;  ///< 1 / depth
};

double dot(const std::array<double, 3>& a, const double b[3]) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

// Keeps the part of a triangle at depth >= near (Sutherland-Hodgman against one plane): 0, 3
// or 4 corners, in order.
int clipNear(const CameraPoint in[3], double near, CameraPoint out[4]) {
  int n = 0;
  for (int k = 0; k < 3; ++k) {
    const CameraPoint& a = in[k];
    const CameraPoint& b = in[(k + 1) % 3];
    const bool a_in = a.z >= near, b_in = b.z >= near;
    if (a_in) out[n++] = a;
    if (a_in != b_in) {
      const double s = (near - a.z) / (b.z - a.z);
      out[n++] = {a.x + (b.x - a.x) * s, a.y + (b.y - a.y) * s, near};
    }
  }
  return n;
}

// Twice the signed area of (a, b, p): which side of the edge a -> b the point p lies on.
double edge(const ScreenPoint& a, const ScreenPoint& b, double px, double py) {
  return (b.x - a.x) * (py - a.y) - (b.y - a.y) * (px - a.x);
}

// An edge's own pixel centres go to one of the two triangles sharing it: the rule flips with
// the edge's direction, and two consistently oriented neighbours walk it in opposite ways.
bool ownsEdge(const ScreenPoint& a, const ScreenPoint& b) {
  return b.y > a.y || (b.y == a.y && b.x < a.x);
}

void drawTriangle(ScreenPoint v0, ScreenPoint v1, ScreenPoint v2, uint32_t id, IdBuffer& buffer) {
  double area = edge(v0, v1, v2.x, v2.y);
  if (area == 0 || !std::isfinite(area)) return;
  if (area < 0) {
    std::swap(v1, v2);
    area = -area;
  }
  const double min_x = std::min({v0.x, v1.x, v2.x}), max_x = std::max({v0.x, v1.x, v2.x});
  const double min_y = std::min({v0.y, v1.y, v2.y}), max_y = std::max({v0.y, v1.y, v2.y});
  // Pixel centres i + 0.5 inside [min, max].
  const double w = buffer.width, h = buffer.height;
  const int64_t i0 = int64_t(std::max(0.0, std::ceil(min_x - 0.5)));
  const int64_t i1 = int64_t(std::min(w - 1, std::floor(max_x - 0.5)));
  const int64_t j0 = int64_t(std::max(0.0, std::ceil(min_y - 0.5)));
  const int64_t j1 = int64_t(std::min(h - 1, std::floor(max_y - 0.5)));
  const bool own12 = ownsEdge(v1, v2), own20 = ownsEdge(v2, v0), own01 = ownsEdge(v0, v1);
  // Each edge function is affine in x along a row, so the pixels it keeps are a half-line
  // starting where it crosses zero, and that crossing moves linearly from row to row:
  // i*(j) = cross0 + cross_step * j. Rows are narrowed to the intersection of the three
  // half-lines, one pixel wider each side against rounding; the exact test below decides.
  const ScreenPoint* from[3] = {&v1, &v2, &v0};
  const ScreenPoint* to[3] = {&v2, &v0, &v1};
  double cross0[3], cross_step[3], constant[3];
  int side[3];  // +1: keeps i >= i*, -1: keeps i <= i*, 0: the row decides alone
  for (int e = 0; e < 3; ++e) {
    const double slope = -(to[e]->y - from[e]->y);
    side[e] = slope > 0 ? 1 : slope < 0 ? -1 : 0;
    const double at_origin = edge(*from[e], *to[e], 0.5, 0.5);  // pixel (0, 0)
    constant[e] = to[e]->x - from[e]->x;                        // d edge / d row
    cross0[e] = side[e] ? -at_origin / slope : 0;
    cross_step[e] = side[e] ? -constant[e] / slope : 0;
    if (!side[e]) cross0[e] = at_origin;
  }
  for (int64_t j = j0; j <= j1; ++j) {
    const double py = double(j) + 0.5;
    double lo = double(i0), hi = double(i1);
    for (int e = 0; e < 3; ++e) {
      if (side[e] > 0) {
        lo = std::max(lo, std::floor(cross0[e] + cross_step[e] * double(j)) - 1);
      } else if (side[e] < 0) {
        hi = std::min(hi, std::ceil(cross0[e] + cross_step[e] * double(j)) + 1);
      } else if (cross0[e] + constant[e] * double(j) < 0) {
        hi = -1;  // a horizontal edge with the whole row outside it
      }
    }
    lo = std::min(lo, double(i1) + 1);
    hi = std::max(hi, double(i0) - 1);
    for (int64_t i = int64_t(lo); i <= int64_t(hi); ++i) {
      const double px = double(i) + 0.5;
      const double e0 = edge(v1, v2, px, py), e1 = edge(v2, v0, px, py), e2 = edge(v0, v1, px, py);
      if (e0 < 0 || e1 < 0 || e2 < 0) continue;
      if ((e0 == 0 && !own12) || (e1 == 0 && !own20) || (e2 == 0 && !own01)) continue;
      // 1 / depth is affine in screen space for a plane: interpolate it barycentrically.
      const double inverse_z = (e0 * v0.inverse_z + e1 * v1.inverse_z + e2 * v2.inverse_z) / area;
      const size_t p = size_t(j) * buffer.width + size_t(i);
      if (inverse_z > buffer.inverse_depth[p] ||
          (inverse_z == buffer.inverse_depth[p] && id < buffer.ids[p])) {
        buffer.inverse_depth[p] = inverse_z;
        buffer.ids[p] = id;
      }
    }
  }
}

}  // namespace

std::array<RasterCamera, 6> cubeFaceCameras(const std::array<double, 3>& eye,
                                            uint32_t resolution_px, double near) {
  // forward, up per face; right = up x forward keeps every face's frame right-handed.
  static constexpr double kFaces[6][2][3] = {
      {{1, 0, 0}, {0, 1, 0}},  {{-1, 0, 0}, {0, 1, 0}}, {{0, 1, 0}, {0, 0, -1}},
      {{0, -1, 0}, {0, 0, 1}}, {{0, 0, 1}, {0, 1, 0}},  {{0, 0, -1}, {0, 1, 0}},
  };
  std::array<RasterCamera, 6> cameras;
  for (int f = 0; f < 6; ++f) {
    RasterCamera& c = cameras[f];
    c.eye = eye;
    const double* fw = kFaces[f][0];
    const double* up = kFaces[f][1];
    c.forward = {fw[0], fw[1], fw[2]};
    c.up = {up[0], up[1], up[2]};
    c.right = {up[1] * fw[2] - up[2] * fw[1], up[2] * fw[0] - up[0] * fw[2],
               up[0] * fw[1] - up[1] * fw[0]};
    c.tan_half_x = c.tan_half_y = 1;
    c.width = c.height = resolution_px;
    c.near = near;
  }
  return cameras;
}

void IdBuffer::reset(const RasterCamera& camera) {
  width = camera.width;
  height = camera.height;
  ids.assign(size_t(width) * height, kNoId);
  inverse_depth.assign(size_t(width) * height, 0.0);
}

void rasterizeTriangles(const RasterCamera& camera, std::span<const float> triangles,
                        std::span<const uint32_t> ids, IdBuffer& buffer) {
  TESSERA_CHECK(triangles.size() == ids.size() * 9) << "rasterizeTriangles: 9 floats per ID";
  TESSERA_CHECK(buffer.width == camera.width && buffer.height == camera.height)
      << "rasterizeTriangles: buffer not reset for the camera";
  const double half_w = camera.width / 2.0, half_h = camera.height / 2.0;
  for (size_t k = 0; k < ids.size(); ++k) {
    CameraPoint corners[3];
    for (int c = 0; c < 3; ++c) {
      const float* p = triangles.data() + 9 * k + 3 * c;
      const double d[3] = {p[0] - camera.eye[0], p[1] - camera.eye[1], p[2] - camera.eye[2]};
      corners[c] = {dot(camera.right, d), dot(camera.up, d), dot(camera.forward, d)};
    }
    if (corners[0].z < camera.near && corners[1].z < camera.near && corners[2].z < camera.near)
      continue;
    CameraPoint clipped[4];
    const int n = clipNear(corners, camera.near, clipped);
    ScreenPoint screen[4];
    for (int c = 0; c < n; ++c) {
      const double inverse_z = 1 / clipped[c].z;
      screen[c] = {(clipped[c].x * inverse_z / camera.tan_half_x + 1) * half_w,
                   (1 - clipped[c].y * inverse_z / camera.tan_half_y) * half_h, inverse_z};
    }
    for (int c = 1; c + 1 < n; ++c)
      drawTriangle(screen[0], screen[c], screen[c + 1], ids[k], buffer);
  }
}

bool boxHidden(const RasterCamera& camera, const std::array<float, 3>& box_min,
               const std::array<float, 3>& box_max, const IdBuffer& buffer) {
  double min_x = INFINITY, max_x = -INFINITY, min_y = INFINITY, max_y = -INFINITY;
  double nearest = 0;  // the largest 1 / depth of the box
  for (int c = 0; c < 8; ++c) {
    const double d[3] = {(c & 1 ? box_max[0] : box_min[0]) - camera.eye[0],
                         (c & 2 ? box_max[1] : box_min[1]) - camera.eye[1],
                         (c & 4 ? box_max[2] : box_min[2]) - camera.eye[2]};
    const double z = dot(camera.forward, d);
    if (z < camera.near) return false;  // crosses the near plane: no rectangle to test
    const double x = dot(camera.right, d) / z / camera.tan_half_x;
    const double y = dot(camera.up, d) / z / camera.tan_half_y;
    min_x = std::min(min_x, (x + 1) * camera.width / 2);
    max_x = std::max(max_x, (x + 1) * camera.width / 2);
    min_y = std::min(min_y, (1 - y) * camera.height / 2);
    max_y = std::max(max_y, (1 - y) * camera.height / 2);
    nearest = std::max(nearest, 1 / z);
  }
  // Every pixel centre the box's projection may hold, one pixel wider against rounding.
  const int64_t i0 = std::max<int64_t>(0, int64_t(std::floor(min_x - 0.5)) - 1);
  const int64_t i1 = std::min<int64_t>(camera.width - 1, int64_t(std::ceil(max_x - 0.5)) + 1);
  const int64_t j0 = std::max<int64_t>(0, int64_t(std::floor(min_y - 0.5)) - 1);
  const int64_t j1 = std::min<int64_t>(camera.height - 1, int64_t(std::ceil(max_y - 0.5)) + 1);
  for (int64_t j = j0; j <= j1; ++j)
    for (int64_t i = i0; i <= i1; ++i)
      if (!(buffer.inverse_depth[size_t(j) * buffer.width + size_t(i)] > nearest)) return false;
  return true;
}

}  // namespace tessera::detail
