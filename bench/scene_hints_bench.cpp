// tessera-scene-hints-bench: average coverage hints (Marvie & Bouatouch, seed 003 part II;
// docs/scenes.md, "Coverage hints") against the projected-size estimate alone, on the same
// camera flights over a simulated link: bytes fetched and time to full quality.
//
//   tessera-scene-hints-bench ARCHIVE [FLIGHTS] [LINK]     (LINK as "20mbit:40ms", the default)
//
// The archive must hold coverage hints (tessera build ... --coverage-hints). Each flight jumps
// to a cell of the hint grid at a seeded random place, eye height and heading, walks forward
// half a cell over 60 frames, then holds; frames are paced at 60 Hz on the wall clock. Each
// flight runs twice on a fresh streamer and a fresh link: hints off, then on. Full quality is
// the first frame from which the held camera has no visible leaf waiting and no visible object
// below its projected-size level (SceneFrameStats: waiting_leaves and missing_pixels 0), the
// same criterion in both modes (hints never change a level once its users have arrived).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <tessera/link.h>
#include <tessera/scene.h>
#include <tessera/scene_stream.h>

namespace {

using tessera::PerspectiveView;
using Clock = std::chrono::steady_clock;

constexpr int kWalkFrames = 60;
constexpr int kMaxFrames = 60 * 60;  // a minute at most per run

struct Flight {
  double x = 0, y = 0, z = 0, heading = 0;
};

// The view frame is z up (forward = (sin yaw cos pitch, -cos yaw cos pitch, sin pitch)); the
// scenes are y up: look along `heading` in the x-z plane, 0.15 rad below the horizon.
PerspectiveView cameraAt(const Flight& f, double step) {
  PerspectiveView camera;
  const double down = 0.15;
  camera.eye_x = f.x + step * std::cos(f.heading);
  camera.eye_y = f.y;
  camera.eye_z = f.z + step * std::sin(f.heading);
  const double fx = std::cos(f.heading) * std::cos(down), fy = -std::sin(down),
               fz = std::sin(f.heading) * std::cos(down);
  camera.pitch_rad = std::asin(fz);
  camera.yaw_rad = std::atan2(fx, -fy);
  camera.fov_y_rad = 1.0;
  camera.viewport_w = 1280;
  camera.viewport_h = 720;
  return camera;
}

std::vector<Flight> flights(const tessera::CoverageHints& h, int count) {
  std::mt19937 rng(28);
  std::uniform_int_distribution<uint32_t> cell(0, h.cellCount() - 1);
  std::uniform_real_distribution<double> unit(0, 1);
  std::vector<Flight> out;
  for (int k = 0; k < count; ++k) {
    const uint32_t c = cell(rng);
    double p[3] = {0, 0, 0};
    p[h.axisU()] = h.origin_u + (c % h.cells_u + unit(rng)) * h.cell_size;
    p[h.axisV()] = h.origin_v + (c / h.cells_u + unit(rng)) * h.cell_size;
    p[h.up_axis] = h.eye_low + unit(rng) * (h.eye_high - h.eye_low);
    out.push_back({p[0], p[1], p[2], unit(rng) * 2 * M_PI});
  }
  return out;
}

struct Run {
  bool full = false;
  int frames = 0;            ///< frames to full quality
  double seconds = 0;        ///< wall time to full quality
  uint64_t bytes_full = 0;   ///< bytes fetched until then
  uint64_t bytes_total = 0;  ///< bytes fetched by the end of the run
  uint32_t hint_only = 0;    ///< textures sized by hints alone, summed over frames
  bool saw = false;          ///< some frame had a visible leaf (else the flight is left out)
};

Run fly(const std::string& path, const tessera::LinkModel& link, const Flight& flight,
        double cell_size, bool hints) {
  Run run;
  auto file = tessera::openFileSource(path);
  if (!file) return run;
  auto source = tessera::makeThrottledSource(*file, link);
  auto archive = tessera::SceneArchive::open(source);
  if (!archive) return run;
  tessera::SceneStreamOptions options;
  options.use_coverage_hints = hints;
  auto streamer = tessera::SceneStreamer::open(*archive, options);
  if (!streamer) {
    std::fprintf(stderr, "%s\n", streamer.error().message.c_str());
    return run;
  }
  const auto start = Clock::now();
  for (int frame = 0; frame < kMaxFrames; ++frame) {
    std::this_thread::sleep_until(start + std::chrono::microseconds(16667) * frame);
    const double step = 0.5 * cell_size * std::min(frame, kWalkFrames) / kWalkFrames;
    const tessera::SceneFrameStats stats = (*streamer)->update(cameraAt(flight, step));
    run.hint_only += stats.hint_only_textures;
    run.saw |= stats.visible_leaves > 0;
    const bool full = frame >= kWalkFrames && stats.waiting_leaves == 0 &&
                      stats.missing_pixels == 0 && stats.visible_leaves > 0;
    if (full && !run.full) {
      run.full = true;
      run.frames = frame;
      run.seconds = std::chrono::duration<double>(Clock::now() - start).count();
      run.bytes_full = (*streamer)->totals().bytes_read;
    }
    if (run.full && frame >= run.frames + 60) break;  // a second more: what else it fetches
    if (!full && run.full) run.full = false;          // not settled yet: keep looking
  }
  run.bytes_total = (*streamer)->totals().bytes_read;
  return run;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s ARCHIVE [FLIGHTS] [LINK]\n", argv[0]);
    return 2;
  }
  const std::string path = argv[1];
  const int count = argc > 2 ? std::max(1, std::atoi(argv[2])) : 6;
  auto link = tessera::parseLinkModel(argc > 3 ? argv[3] : "20mbit:40ms");
  auto archive = tessera::SceneArchive::openFile(path);
  if (!link || !archive) {
    std::fprintf(stderr, "%s\n", (!link ? link.error() : archive.error()).message.c_str());
    return 1;
  }
  auto hints = (*archive)->readCoverageHints();
  if (!hints) {
    std::fprintf(stderr, "%s (build with --coverage-hints)\n", hints.error().message.c_str());
    return 1;
  }
  std::printf("%s: %u objects, %u textures; %u x %u hint cells of %.1f; link %s\n", path.c_str(),
              (*archive)->summary().objects, (*archive)->summary().textures, hints->cells_u,
              hints->cells_v, hints->cell_size, argc > 3 ? argv[3] : "20mbit:40ms");
  std::printf("flight  mode   full  frames  seconds  MB_to_full  MB_total  hint_only\n");
  double sum[2][3] = {{0, 0, 0}, {0, 0, 0}};
  int settled[2] = {0, 0}, flown[2] = {0, 0};
  const std::vector<Flight> all = flights(*hints, count);
  for (size_t k = 0; k < all.size(); ++k) {
    for (int mode = 0; mode < 2; ++mode) {
      const Run r = fly(path, *link, all[k], hints->cell_size, mode == 1);
      if (!r.saw) {
        std::printf("%6zu  %-5s  sees nothing: left out\n", k, mode ? "hints" : "off");
        continue;
      }
      std::printf("%6zu  %-5s  %4s  %6d  %7.2f  %10.2f  %8.2f  %9u\n", k, mode ? "hints" : "off",
                  r.full ? "yes" : "no", r.frames, r.seconds, r.bytes_full / 1e6,
                  r.bytes_total / 1e6, r.hint_only);
      settled[mode] += r.full;
      ++flown[mode];
      sum[mode][0] += r.full ? r.seconds : 60;
      sum[mode][1] += r.full ? r.frames : kMaxFrames;
      sum[mode][2] += double(r.bytes_total);
    }
    std::fflush(stdout);
  }
  for (int mode = 0; mode < 2; ++mode)
    std::printf(
        "%-5s: %d/%d reached full quality (a minute counted for the others); total %.2f s, "
        "%.0f frames, %.2f MB fetched\n",
        mode ? "hints" : "off", settled[mode], flown[mode], sum[mode][0], sum[mode][1],
        sum[mode][2] / 1e6);
  std::printf("hints vs off: time to full quality %+.1f %%, frames %+.1f %%, bytes %+.1f %%\n",
              100 * (sum[1][0] / sum[0][0] - 1), 100 * (sum[1][1] / sum[0][1] - 1),
              100 * (sum[1][2] / sum[0][2] - 1));
  return 0;
}
