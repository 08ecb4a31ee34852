#include "scene_path.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>

#include <fmt/format.h>

namespace tessera::cli {

namespace {

constexpr double kPi = std::numbers::pi;
/// Bounds of a keyframe time (a day), as image paths have.
constexpr double kMaxPathS = 86400;

}  // namespace

ScenePose lookAt(double x, double y, double z, double tx, double ty, double tz) {
  const double dx = tx - x, dy = ty - y, dz = tz - z;
  ScenePose pose{x, y, z, 0, -kPi / 2};
  if (dx == 0 && dy == 0 && dz == 0) return pose;
  pose.yaw_rad = dx == 0 && dz == 0 ? 0 : std::atan2(dx, -dz);
  pose.pitch_rad = std::atan2(dy, std::hypot(dx, dz));
  return pose;
}

PerspectiveView perspectiveOf(const ScenePose& pose, double fov_y_rad, uint32_t viewport_w,
                              uint32_t viewport_h) {
  const double cp = std::cos(pose.pitch_rad);
  // Forward in the scene's world, which is also the PerspectiveView's frame.
  const Vec3 f{std::sin(pose.yaw_rad) * cp, std::sin(pose.pitch_rad), -std::cos(pose.yaw_rad) * cp};
  // The screen's right is horizontal, (cos yaw, 0, sin yaw); the view's basis.right is its
  // opposite (mirrored basis, see the header).
  const Vec3 right{-std::cos(pose.yaw_rad), 0, -std::sin(pose.yaw_rad)};
  PerspectiveView view;
  view.eye_x = pose.x;
  view.eye_y = pose.y;
  view.eye_z = pose.z;
  view.fov_y_rad = fov_y_rad;
  view.viewport_w = viewport_w;
  view.viewport_h = viewport_h;
  view.pitch_rad = std::asin(std::clamp(f.z, -1.0, 1.0));
  view.yaw_rad = std::hypot(f.x, f.y) > 1e-12 ? std::atan2(f.x, -f.y) : 0;
  // Roll turns the basis right at roll 0, r0, about forward onto `right`.
  const Vec3 r0{std::cos(view.yaw_rad), std::sin(view.yaw_rad), 0};
  const CameraBasis flat = cameraBasis(view);
  const double along_r0 = right.x * r0.x + right.y * r0.y + right.z * r0.z;
  const double along_up = right.x * flat.up.x + right.y * flat.up.y + right.z * flat.up.z;
  view.roll_rad = std::atan2(along_up, along_r0);
  return view;
}

ScenePose ScenePath::at(double t_s) const {
  if (keys.empty()) return {};
  if (t_s <= keys.front().t_s) return keys.front().pose;
  if (t_s >= keys.back().t_s) return keys.back().pose;
  const auto next = std::upper_bound(keys.begin(), keys.end(), t_s,
                                     [](double t, const SceneKeyframe& k) { return t < k.t_s; });
  const SceneKeyframe& b = *next;
  const SceneKeyframe& a = *(next - 1);
  if (b.jump || b.t_s <= a.t_s) return a.pose;
  const double s = (t_s - a.t_s) / (b.t_s - a.t_s);
  auto mix = [s](double u, double v) { return u + (v - u) * s; };
  double turn = std::remainder(b.pose.yaw_rad - a.pose.yaw_rad, 2 * kPi);
  return {mix(a.pose.x, b.pose.x), mix(a.pose.y, b.pose.y), mix(a.pose.z, b.pose.z),
          a.pose.yaw_rad + turn * s, mix(a.pose.pitch_rad, b.pose.pitch_rad)};
}

std::vector<SceneStop> ScenePath::stops() const {
  std::vector<SceneStop> out;
  for (size_t i = 0; i + 1 < keys.size(); ++i) {
    if (keys[i + 1].pose != keys[i].pose || keys[i + 1].jump || !(keys[i + 1].t_s > keys[i].t_s))
      continue;
    const bool continues = i > 0 && !out.empty() && out.back().until_s == keys[i].t_s &&
                           !keys[i].jump && keys[i - 1].pose == keys[i].pose;
    if (continues)
      out.back().until_s = keys[i + 1].t_s;  // one stop over several keyframes
    else
      out.push_back({keys[i].t_s, keys[i + 1].t_s});
  }
  return out;
}

ScenePath orbitPath(const SceneSummary& scene, double duration_s) {
  const Box3& b = scene.bounds;
  const double cx = (double(b.min[0]) + b.max[0]) / 2, cz = (double(b.min[2]) + b.max[2]) / 2;
  const double half = std::max(double(b.max[0]) - b.min[0], double(b.max[2]) - b.min[2]) / 2;
  const double radius = 0.7 * half, height = double(b.max[1]) + 0.15 * half;
  ScenePath path;
  path.name = "orbit";
  auto key = [&](double t, double angle) {
    const double x = cx + radius * std::sin(angle), z = cz + radius * std::cos(angle);
    path.keys.push_back({t, lookAt(x, height, z, cx, b.min[1], cz), false});
  };
  // Half a turn in 12 steps, still, the other half, still: stops to time full quality.
  const double d = std::max(duration_s, 0.1);
  for (int i = 0; i <= 12; ++i) key(0.3 * d * i / 12, kPi * i / 12);
  key(0.5 * d, kPi);
  for (int i = 1; i <= 12; ++i) key(0.5 * d + 0.3 * d * i / 12, kPi + kPi * i / 12);
  key(d, 2 * kPi);
  return path;
}

Result<ScenePath> loadScenePathFile(const std::string& file) {
  std::ifstream in(file);
  if (!in) return fail(ErrorCode::kNotFound, file + ": cannot open the path file");
  ScenePath path;
  path.name = file;
  std::string line;
  for (int line_number = 1; std::getline(in, line); ++line_number) {
    if (auto hash = line.find('#'); hash != std::string::npos) line.resize(hash);
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    auto bad = [&](const std::string& why) {
      return fail(ErrorCode::kInvalidArgument, fmt::format("{}:{}: {}", file, line_number, why));
    };
    std::istringstream fields(line);
    std::vector<std::string> words;
    for (std::string word; fields >> word;) words.push_back(word);
    SceneKeyframe key;
    if (!words.empty() && words.back() == "jump") {
      key.jump = true;
      words.pop_back();
    }
    const bool look = words.size() == 8 && words[4] == "look";
    if (look) words.erase(words.begin() + 4);
    if (words.size() != (look ? 7u : 6u))
      return bad("expected 't x y z yaw_deg pitch_deg [jump]' or 't x y z look tx ty tz [jump]'");
    std::vector<double> v;
    for (const std::string& word : words) {
      double value = 0;
      std::istringstream number(word);
      if (!(number >> value) || !number.eof() || !std::isfinite(value))
        return bad(fmt::format("'{}' is not a finite number", word));
      v.push_back(value);
    }
    key.t_s = v[0];
    key.pose = look ? lookAt(v[1], v[2], v[3], v[4], v[5], v[6])
                    : ScenePose{v[1], v[2], v[3], v[4] * kPi / 180, v[5] * kPi / 180};
    if (!look && !(std::abs(v[5]) <= 90))
      return bad(fmt::format("pitch {} is not in [-90, 90] degrees", v[5]));
    if (!(key.t_s >= 0 && key.t_s <= kMaxPathS))
      return bad(fmt::format("time {} is not in [0, {:g}] seconds", key.t_s, kMaxPathS));
    if (!path.keys.empty() && key.t_s < path.keys.back().t_s) return bad("times must not decrease");
    path.keys.push_back(key);
  }
  if (path.keys.empty()) return fail(ErrorCode::kInvalidArgument, file + ": no keyframes");
  return path;
}

std::optional<Box3> viewCellBox(const CoverageHints& hints, const PerspectiveView& camera,
                                const Box3& scene_bounds) {
  const double eye[3] = {camera.eye_x, camera.eye_y, camera.eye_z};
  const int64_t cell = hints.cellAt(eye);
  if (cell < 0) return std::nullopt;
  const uint32_t i = uint32_t(cell) % hints.cells_u, j = uint32_t(cell) / hints.cells_u;
  Box3 box = scene_bounds;
  box.min[hints.axisU()] = hints.origin_u + float(i) * hints.cell_size;
  box.max[hints.axisU()] = hints.origin_u + float(i + 1) * hints.cell_size;
  box.min[hints.axisV()] = hints.origin_v + float(j) * hints.cell_size;
  box.max[hints.axisV()] = hints.origin_v + float(j + 1) * hints.cell_size;
  return box;
}

}  // namespace tessera::cli
