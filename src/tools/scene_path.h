#pragma once
// Camera paths through a 3D scene for `tessera fly SCENE.tess` and the pose of `tessera view`'s
// walk and fly controls (docs/fly.md, "Scenes"): a pose in the scene's y-up world, keyframe
// files, the built-in orbit, and the PerspectiveView the streamer and renderer take.

#include <optional>
#include <string>
#include <vector>

#include <tessera/coverage_hints.h>
#include <tessera/result.h>
#include <tessera/scene.h>
#include <tessera/view.h>

namespace tessera::cli {

/// The vertical field of view of scene flights and `tessera view` on a scene.
inline constexpr double kSceneFovYRad = 1.0;

/// A camera in a scene's world (x east, y up, z south as the importers write it).
struct ScenePose {
  double x = 0, y = 0, z = 0;
  double yaw_rad = 0;    ///< heading about +y: 0 looks towards -z, pi/2 towards +x
  double pitch_rad = 0;  ///< above the horizon; -pi/2 straight down
  friend bool operator==(const ScenePose&, const ScenePose&) = default;
};

/// The pose at (x, y, z) looking at (tx, ty, tz); straight down when the two coincide.
ScenePose lookAt(double x, double y, double z, double tx, double ty, double tz);

/// The PerspectiveView of a pose: its forward, and its roll chosen so that the world's up is
/// the screen's up (the scene renderer draws screen x along -right: PerspectiveView's basis
/// is mirrored, up = forward x right, and the scene's world is right-handed).
PerspectiveView perspectiveOf(const ScenePose& pose, double fov_y_rad, uint32_t viewport_w,
                              uint32_t viewport_h);

struct SceneKeyframe {
  double t_s = 0;
  ScenePose pose;
  bool jump = false;  ///< a teleport: no interpolation from the previous keyframe
};

/// A time the camera stands still: two consecutive keyframes with one pose.
struct SceneStop {
  double from_s = 0;
  double until_s = 0;
};

struct ScenePath {
  std::string name;
  std::vector<SceneKeyframe> keys;  ///< sorted by time
  double durationS() const { return keys.empty() ? 0 : keys.back().t_s; }
  /// The pose at `t_s` (clamped to the path): position linear, heading the short way round.
  ScenePose at(double t_s) const;
  std::vector<SceneStop> stops() const;
};

/// The built-in path "orbit": around the scene's centre at 0.7 of its half-extent and a
/// quarter of it above the ground, looking at the centre; half a turn, a still fifth of the
/// duration, the other half, and a still last fifth.
ScenePath orbitPath(const SceneSummary& scene, double duration_s);

/// Reads a scene keyframe file (docs/fly.md, "Scenes"): one keyframe per line,
/// "t x y z yaw_deg pitch_deg [jump]" or "t x y z look tx ty tz [jump]"; '#' comments. Errors
/// name the file and line.
[[nodiscard]] Result<ScenePath> loadScenePathFile(const std::string& path);

/// The view cell of coverage hints holding the eye of `camera`, as a box: the cell's ground
/// rectangle, spanning `scene_bounds` along the up axis; nullopt when the eye is outside the
/// grid (CoverageHints::cellAt).
std::optional<Box3> viewCellBox(const CoverageHints& hints, const PerspectiveView& camera,
                                const Box3& scene_bounds);

}  // namespace tessera::cli
