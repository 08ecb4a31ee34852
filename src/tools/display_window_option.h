#pragma once
// The display window options `tessera view` and `tessera fly` share: --window and --gamma
// (docs/view.md, "Display window").

#include <string>

#include <tessera/archive.h>
#include <tessera/display_window.h>

namespace tessera::cli {

inline constexpr const char* kWindowOptionHelp =
    "Window/level of 16-bit and float images: MIN,MAX (sample values), pLOW,pHIGH "
    "(percentiles of a coarse level) or auto (the archive's statistics, else p1,p99)";
inline constexpr const char* kGammaOptionHelp =
    "Gamma of the display window: shown = t^GAMMA, t the windowed value in [0, 1]";

/// The window `--window` and `--gamma` ask for, resolved for `image` of `archive`; the error
/// names the option.
inline Result<DisplayWindow> displayWindowFromOptions(const Archive& archive, uint32_t image,
                                                      const std::string& window,
                                                      const std::string& gamma) {
  DisplayWindowRequest request;
  if (Result<void> parsed = parseDisplayWindow(window, request); !parsed)
    return fail(ErrorCode::kInvalidArgument, "--window: " + parsed.error().message);
  Result<double> parsed_gamma = parseGamma(gamma);
  if (!parsed_gamma)
    return fail(ErrorCode::kInvalidArgument, "--gamma: " + parsed_gamma.error().message);
  request.gamma = *parsed_gamma;
  return resolveDisplayWindow(archive, image, request);
}

}  // namespace tessera::cli
