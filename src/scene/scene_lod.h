#pragma once
// Per-object level of detail for a perspective camera (issue 28, item 5): the view frustum
// against boxes, and the texture level an object's projected texel density needs. Pure
// arithmetic; thread-safe.

#include <array>
#include <cstdint>

#include <tessera/scene.h>
#include <tessera/view.h>

namespace tessera::detail {

/// The five planes bounding a camera's view (left, right, bottom, top, near through the eye);
/// a point p is inside when dot(normal[i], p - eye) <= 0 for every i.
struct Frustum {
  Vec3 eye;
  std::array<Vec3, 5> normal;
};

Frustum frustumOf(const PerspectiveView& camera);

/// False only when the box lies wholly outside one plane (conservative: a box near a corner
/// may be reported visible).
bool boxMayBeVisible(const Frustum& frustum, const Box3& box);

/// True when the whole box is inside every plane: its contents need no test of their own.
bool boxInside(const Frustum& frustum, const Box3& box);

/// The longest of the box's three sides.
double longestSide(const Box3& box);

/// Distance from the eye to the nearest point of the box; 0 inside it.
double distanceToBox(const PerspectiveView& camera, const Box3& box);

/// What a visible object needs of one of its textures.
struct ObjectLod {
  /// The finest level the screen can resolve: floor(log2(rho) + bias) clamped to the
  /// texture's levels, with rho = level-0 texels per screen pixel at the object's nearest
  /// point. The texture is taken to span the object's longest box side once (its uv square
  /// stretched over the longest side; textures repeated across a face need finer levels than
  /// this estimate): rho = max(w, h) * d * pixelAngle / longest side, the screen-space
  /// derivative bound at distance d. An eye inside the box (d = 0) gets level 0.
  uint32_t level = 0;
  /// Screen pixels the object covers at most: (longest side / (d * pixelAngle))^2, clamped
  /// to the viewport; what the screen misses while the level is not resident.
  uint64_t pixels = 0;
};

ObjectLod objectLod(const PerspectiveView& camera, const Box3& bounds, const ImageInfo& texture,
                    double lod_bias);

/// What objectLod computes once per frame, for the per-object loop of a frame with thousands
/// of objects (no tan or log2 per object).
struct LodFrame {
  PerspectiveView camera;
  double pixel_angle = 0;  ///< pixelAngle(camera)
  double viewport_px = 0;  ///< w * h
  double bias_scale = 1;   ///< 2^lod_bias: floor(log2(rho) + bias) = floor(log2(rho * scale))
};
LodFrame lodFrame(const PerspectiveView& camera, double lod_bias);
/// objectLod with the frame's constants; the same result.
ObjectLod objectLod(const LodFrame& frame, const Box3& bounds, const ImageInfo& texture);

/// The part of objectLod that depends on the object only, computed once for its textures.
struct ObjectScale {
  double pixels_across = 0;  ///< screen pixels the longest side spans; 0: no extent
  bool eye_inside = false;
  uint64_t pixels = 0;
};
ObjectScale objectScale(const LodFrame& frame, const Box3& bounds);
/// objectLod's level from the object's scale.
uint32_t levelFor(const LodFrame& frame, const ObjectScale& scale, const ImageInfo& texture);

}  // namespace tessera::detail
