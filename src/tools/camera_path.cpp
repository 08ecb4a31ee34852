#include "camera_path.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include <fmt/format.h>

namespace tessera::cli {

namespace {

/// The longest path: a day. Longer keyframe times are surely typos, and a built-in path's
/// keyframes grow with its duration.
constexpr double kMaxPathS = 86400;

}  // namespace

OrthoView CameraPath::at(double t_s, uint32_t viewport_w, uint32_t viewport_h) const {
  OrthoView view;
  view.viewport_w = viewport_w;
  view.viewport_h = viewport_h;
  if (keys.empty()) return view;
  t_s = std::clamp(t_s, keys.front().t_s, keys.back().t_s);
  size_t i = 1;
  while (i < keys.size() && keys[i].t_s < t_s) ++i;
  const Keyframe& b = keys[std::min(i, keys.size() - 1)];
  const Keyframe& a = keys[i - 1 < keys.size() ? i - 1 : 0];
  double span = b.t_s - a.t_s;
  double u = (span > 0 && !b.jump) ? (t_s - a.t_s) / span : (t_s >= b.t_s ? 1.0 : 0.0);
  if (b.jump && t_s < b.t_s) u = 0;
  view.centre_x = a.x + (b.x - a.x) * u;
  view.centre_y = a.y + (b.y - a.y) * u;
  // Zoom interpolates geometrically so the zoom speed is constant on screen.
  view.texels_per_pixel = a.texels_per_pixel * std::pow(b.texels_per_pixel / a.texels_per_pixel, u);
  view.rotation_rad = a.rotation_rad + (b.rotation_rad - a.rotation_rad) * u;
  return view;
}

bool CameraPath::jumpsBetween(double t0, double t1) const {
  for (const Keyframe& key : keys)
    if (key.jump && key.t_s > t0 && key.t_s <= t1) return true;
  return false;
}

Result<CameraPath> builtinPath(const std::string& name, const ImageInfo& image, double speed_px_s,
                               double duration_s, uint32_t viewport_w, uint32_t viewport_h) {
  CameraPath path;
  path.name = name;
  const double w = image.width_px, h = image.height_px;
  const double half_w = viewport_w / 2.0, half_h = viewport_h / 2.0;
  if (!(speed_px_s > 0) || !std::isfinite(speed_px_s) || !(duration_s > 0) ||
      !(duration_s <= kMaxPathS))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("path '{}': speed {} and duration {} must be finite and above 0 "
                            "(duration at most {:g} s)",
                            name, speed_px_s, duration_s, kMaxPathS));
  if (name == "pan") {
    // Left to right through the middle at full detail, bouncing at the edges.
    double x0 = std::min(half_w, w / 2), x1 = std::max(w - half_w, w / 2);
    if (x1 - x0 < 1) {  // the image fits the view: nowhere to go (and no leg to bounce on)
      path.keys = {{0, x0, h / 2, 1}, {duration_s, x0, h / 2, 1}};
      return path;
    }
    double t = 0, x = x0;
    bool forward = true;
    path.keys.push_back({0, x, h / 2, 1});
    while (t < duration_s) {
      double target = forward ? x1 : x0;
      double leg_s = std::max(std::abs(target - x) / speed_px_s, 1e-3);
      double step = std::min(leg_s, duration_s - t);
      x += (target - x) * (step / leg_s);
      t += step;
      path.keys.push_back({t, x, h / 2, 1});
      forward = !forward;
    }
  } else if (name == "zoom") {
    double whole = std::max(w / viewport_w, h / viewport_h);
    path.keys = {{0, w / 2, h / 2, std::max(1.0, whole)},
                 {duration_s / 2, w / 2, h / 2, 1},
                 {duration_s, w / 2, h / 2, std::max(1.0, whole)}};
  } else if (name == "jump") {
    // Five spread positions at full detail; each held for an equal share of the duration.
    const double spots[5][2] = {{0.5, 0.5}, {0.2, 0.25}, {0.8, 0.7}, {0.3, 0.8}, {0.75, 0.2}};
    double hold = duration_s / 5;
    for (int i = 0; i < 5; ++i) {
      Keyframe key{i * hold, spots[i][0] * w, spots[i][1] * h, 1, 0, i > 0};
      path.keys.push_back(key);
      path.keys.push_back({(i + 1) * hold - 1e-6, key.x, key.y, 1});
    }
  } else if (name == "spiral") {
    // An Archimedean spiral from the centre whose path speed is `speed_px_s`.
    double r_step = std::max(half_w, half_h) * 2;  // radius gained per turn
    double t = 0, angle = 0;
    while (t <= duration_s) {
      double r = r_step * angle / (2 * M_PI);
      path.keys.push_back({t, w / 2 + r * std::cos(angle), h / 2 + r * std::sin(angle), 1});
      double dt = 0.05;
      double ds = speed_px_s * dt;
      angle += ds / std::max(r, r_step / 4);
      t += dt;
    }
  } else {
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("unknown path '{}' (pan, zoom, jump, spiral or a file)", name));
  }
  return path;
}

Result<CameraPath> loadPathFile(const std::string& file) {
  std::ifstream in(file);
  if (!in) return fail(ErrorCode::kNotFound, file + ": cannot open the path file");
  CameraPath path;
  path.name = file;
  std::string line;
  int line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    if (auto hash = line.find('#'); hash != std::string::npos) line.resize(hash);
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;  // blank or comment
    std::istringstream fields(line);
    Keyframe key;
    if (!(fields >> key.t_s >> key.x >> key.y >> key.texels_per_pixel))
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}:{}: expected 't x y texels_per_pixel [rotation] [jump]'", file,
                              line_number));
    std::string word;
    if (fields >> word) {
      if (word == "jump") {
        key.jump = true;
      } else {
        try {
          key.rotation_rad = std::stod(word);
        } catch (...) {
          return fail(
              ErrorCode::kInvalidArgument,
              fmt::format("{}:{}: '{}' is neither a rotation nor 'jump'", file, line_number, word));
        }
        if (fields >> word) {
          if (word != "jump")
            return fail(ErrorCode::kInvalidArgument,
                        fmt::format("{}:{}: '{}' is not 'jump'", file, line_number, word));
          key.jump = true;
        }
      }
      if (fields >> word)
        return fail(ErrorCode::kInvalidArgument,
                    fmt::format("{}:{}: '{}' after the last field", file, line_number, word));
    }
    if (!(key.texels_per_pixel > 0) || !std::isfinite(key.texels_per_pixel) ||
        !std::isfinite(key.x) || !std::isfinite(key.y) || !std::isfinite(key.rotation_rad))
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}:{}: texels_per_pixel must be > 0 and positions finite", file,
                              line_number));
    if (!(key.t_s >= 0 && key.t_s <= kMaxPathS))
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}:{}: time {} is not in [0, {:g}] seconds", file, line_number,
                              key.t_s, kMaxPathS));
    if (!path.keys.empty() && key.t_s < path.keys.back().t_s)
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}:{}: times must not decrease", file, line_number));
    path.keys.push_back(key);
  }
  if (path.keys.empty()) return fail(ErrorCode::kInvalidArgument, file + ": no keyframes");
  return path;
}

}  // namespace tessera::cli
