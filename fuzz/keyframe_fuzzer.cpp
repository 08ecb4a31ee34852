// Fuzzes the keyframe file reader of `tessera fly --path FILE` (src/tools/camera_path.cpp):
// the input is written to a file and loaded. Checks that an accepted path is sorted by time,
// has finite, positive zooms, and evaluates to finite views everywhere.
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <string>

#include "camera_path.h"
#include "format_fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace tessera;
  static const std::string path =
      "/tmp/tessera_keyframe_fuzz_" + std::to_string(::getpid()) + ".path";
  std::FILE* file = std::fopen(path.c_str(), "wb");
  if (file == nullptr) fuzz::die("keyframe_fuzzer", "cannot write the input file");
  std::fwrite(data, 1, size, file);
  std::fclose(file);
  Result<cli::CameraPath> loaded = cli::loadPathFile(path);
  if (!loaded) return 0;
  const cli::CameraPath& camera = *loaded;
  for (size_t i = 0; i < camera.keys.size(); ++i) {
    const cli::Keyframe& key = camera.keys[i];
    if (!std::isfinite(key.t_s) || !std::isfinite(key.x) || !std::isfinite(key.y) ||
        !std::isfinite(key.texels_per_pixel) || !(key.texels_per_pixel > 0) ||
        !std::isfinite(key.rotation_rad))
      fuzz::die("keyframe_fuzzer", "accepted a keyframe that is not finite and positive");
    if (i > 0 && key.t_s < camera.keys[i - 1].t_s) fuzz::die("keyframe_fuzzer", "unsorted");
  }
  const double duration = camera.durationS();
  for (int step = 0; step <= 16; ++step) {
    const OrthoView view = camera.at(duration * step / 16, 640, 480);
    if (!std::isfinite(view.centre_x) || !std::isfinite(view.centre_y) ||
        !std::isfinite(view.texels_per_pixel) || !(view.texels_per_pixel > 0))
      fuzz::die("keyframe_fuzzer", "a view along the path is not finite");
  }
  return 0;
}
