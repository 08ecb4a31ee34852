#pragma once
// A deterministic CPU rasterizer of triangle IDs with a depth buffer, for the offline average
// coverage hints (Marvie & Bouatouch, seed 003 part II: render each texture in a unique colour
// and count pixels). The builder has no GL; this one is small, exact at pixel centres and the
// same on every machine. Pure; thread-safe (the buffer is the caller's).

#include <array>
#include <cstdint>
#include <span>
#include <vector>

namespace tessera::detail {

/// A pinhole camera: pixel (i, j) samples the ray through its centre, eye + t (forward +
/// right * tan_half_x * (2 (i + 0.5) / width - 1) + up * tan_half_y * (1 - 2 (j + 0.5) /
/// height)), with camera depth t (the distance along forward) at least near.
struct RasterCamera {
  std::array<double, 3> eye{0, 0, 0};
  std::array<double, 3> right{1, 0, 0}, up{0, 1, 0}, forward{0, 0, 1};  ///< orthonormal
  double tan_half_x = 1, tan_half_y = 1;
  uint32_t width = 64, height = 64;
  double near = 1e-3;  ///< > 0
};

/// The six 90-degree cube-face cameras at `eye`, looking along +x, -x, +y, -y, +z, -z.
std::array<RasterCamera, 6> cubeFaceCameras(const std::array<double, 3>& eye,
                                            uint32_t resolution_px, double near);

inline constexpr uint32_t kNoId = 0xFFFFFFFFu;

/// What a camera sees: per pixel, row-major from the top-left, the ID of the nearest triangle
/// whose interior (or top-left edge) holds the pixel centre's ray, or kNoId.
struct IdBuffer {
  uint32_t width = 0, height = 0;
  std::vector<uint32_t> ids;
  std::vector<double> inverse_depth;  ///< 1 / camera depth of the nearest hit; 0: none

  /// Sized for `camera` and cleared to kNoId.
  void reset(const RasterCamera& camera);
};

/// Draws triangles (9 floats each, world space: x, y, z of three corners) with one ID each into
/// `buffer` (reset for `camera`): clipped against the near plane, both faces drawn, depth
/// tested per pixel centre on 1 / depth (exact for planes under perspective), the nearer
/// winning and an exact tie going to the lower ID, so the picture does not depend on the draw
/// order. A pixel centre exactly on an edge belongs to the triangle for which the edge is a
/// top or left edge, so two triangles sharing an edge never both take it.
void rasterizeTriangles(const RasterCamera& camera, std::span<const float> triangles,
                        std::span<const uint32_t> ids, IdBuffer& buffer);

/// True when every pixel centre the box could project onto already holds something strictly
/// nearer than the box's nearest corner: nothing inside the box can change the buffer, so a
/// caller drawing front to back may skip it. False for a box crossing the near plane.
bool boxHidden(const RasterCamera& camera, const std::array<float, 3>& box_min,
               const std::array<float, 3>& box_max, const IdBuffer& buffer);

}  // namespace tessera::detail
