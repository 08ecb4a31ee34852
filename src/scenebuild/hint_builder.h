#pragma once
// Offline average coverage hints (Marvie & Bouatouch, seed 003 part II; docs/scenes.md,
// "Coverage hints"): a regular grid of view cells over the scene's ground; from 8 positions
// per cell, 6 cube faces each, the objects are drawn with their index as ID (id_raster.h),
// every pixel weighted by its solid angle, and each texture an object uses is credited with
// the object's pixels; per cell the shares are normalised by the whole sampled sphere and
// quantised. Owned by one thread (it runs its own fixed pool of `threads` workers).

#include <array>
#include <cstdint>
#include <vector>

#include <tessera/coverage_hints.h>
#include <tessera/result.h>

#include "format/scene.h"

namespace tessera::detail {

/// The scene as the hint builder draws it: world-space triangles per object.
struct HintScene {
  std::vector<float> triangles;        ///< 9 floats per triangle, world space
  std::vector<uint32_t> object_first;  ///< objects + 1: object o's triangles [first[o], [o + 1])
  std::vector<SceneBox> object_bounds;
  /// Per object, the archive's texture indices of its slots (kNoSceneTexture for none).
  std::vector<std::array<uint32_t, kSceneTextureSlots>> object_textures;
  uint32_t texture_count = 0;
  SceneBox bounds;  ///< of every object
  uint32_t objectCount() const { return uint32_t(object_bounds.size()); }
};

struct HintBuildOptions {
  /// Side of a square cell in world units; 0: the longer ground side of the bounds / 16.
  double cell_size = 0;
  uint32_t resolution_px = 64;  ///< per cube face, 1..4096
  uint32_t threads = 1;
  /// Objects whose bounding sphere spans fewer face pixels than this (at the face centre's
  /// pixel size) are not drawn from that position: they could cover about a pixel at most.
  /// 0 draws everything (the tests' exact comparison).
  double min_object_px = 1;
  uint32_t up_axis = 1;  ///< the generator, glTF and the .stg importer are y-up
};

struct HintBuildStats {
  uint64_t views = 0;          ///< cube faces drawn
  uint64_t objects_drawn = 0;  ///< (view position, object) pairs not culled
  double seconds = 0;
};

/// The grid (no entries yet) the options and bounds give: cells, origin, eye heights.
CoverageHints hintGrid(const HintScene& scene, const HintBuildOptions& options);

/// The eye positions sampled in cell `cell` of `grid`: the centres of the 8 octants of the box
/// spanning the cell on the ground and [eye_low, eye_high] along up, i.e. the cell's quarter
/// points on the ground at both heights.
std::vector<std::array<double, 3>> cellEyePositions(const CoverageHints& grid, uint32_t cell);

/// Per face pixel (row-major), the pixel's solid angle in steradians.
std::vector<double> facePixelSolidAngles(uint32_t resolution_px);

/// Computes every cell's hints. Deterministic: the same scene and options give the same bytes
/// whatever the thread count. Fails (kInvalidArgument) on options out of range.
[[nodiscard]] Result<CoverageHints> buildCoverageHints(const HintScene& scene,
                                                       const HintBuildOptions& options,
                                                       HintBuildStats* stats = nullptr);

/// Quantises a share of the sampled sphere: round(share * 65535) clamped to 1..65535, so any
/// texture seen at all keeps an entry.
uint16_t quantiseCoverage(double share);

}  // namespace tessera::detail
