#pragma once
/// \file
/// The window/level mapping that shows 16-bit and float samples on an 8-bit display
/// (docs/rendering.md, "Display window"): a colour sample v becomes
///
///     t = clamp((v - low) / (high - low), 0, 1),   shown = t ^ gamma
///
/// Alpha is not windowed: u16 alpha is a / 65535, f32 alpha is clamped to [0, 1], u8 as stored.
/// A texel with a NaN sample is no data: transparent black. The GL renderers apply the same
/// formula in their shaders; `tessera serve` applies it to the tiles it maps to 8 bits.

#include <cstdint>
#include <string>
#include <string_view>

#include <tessera/archive.h>
#include <tessera/result.h>

namespace tessera {

/// A resolved window: sample values `low` and `high` map to 0 and 1, then `gamma` applies.
/// low < high, gamma > 0.
struct DisplayWindow {
  double low = 0;
  double high = 255;
  double gamma = 1;
};

/// How a window is asked for (the `--window` option and the server's `window=` query).
struct DisplayWindowRequest {
  enum class Kind : uint8_t {
    kAuto,         ///< the archive's statistics, else percentiles 1 and 99 of a coarse level
    kValues,       ///< `first`, `second` are the low and high sample values
    kPercentiles,  ///< `first`, `second` are percentiles (0-100) of a coarse level
  };
  Kind kind = Kind::kAuto;
  double first = 0;
  double second = 0;
  double gamma = 1;
};

/// Parses "MIN,MAX", "auto" or "pLOW,pHIGH" (e.g. "p1,p99") into `request` (gamma untouched).
/// The error names the text and what is wrong with it (kInvalidArgument).
[[nodiscard]] Result<void> parseDisplayWindow(std::string_view text, DisplayWindowRequest& request);
/// Parses a gamma: a finite number above 0 (kInvalidArgument otherwise).
[[nodiscard]] Result<double> parseGamma(std::string_view text);

/// The window that shows `image` of `archive` unchanged: 0-255 for u8, 0-65535 for u16, 0-1
/// for f32.
DisplayWindow fullRangeWindow(SampleType type);

/// Resolves `request` for `image` of `archive`. kAuto takes the colour channels' lowest
/// "min" and highest "max" of the image's metadata statistics (docs/format.md, "Metadata")
/// when the image is u16 or f32 and they are present, else percentiles 1 and 99; u8 images
/// resolve kAuto to the full range. Percentiles are taken over the finite colour samples of
/// the finest level of at most 512 x 512 texels (one or a few tile reads). A window whose
/// ends meet is widened to one sample step (1 for u8/u16, else 1e-6 of the value or 1e-6).
/// Fails with the archive's error when that level cannot be read. Any thread.
[[nodiscard]] Result<DisplayWindow> resolveDisplayWindow(const Archive& archive, uint32_t image,
                                                         const DisplayWindowRequest& request);

/// One colour sample mapped by `window` to 0-255 (round to nearest). NaN maps to 0.
uint8_t windowSample(double value, const DisplayWindow& window);

/// Maps an image of any sample type to RGBA8 by `window` (grey as (g, g, g, a), missing alpha
/// 255), NaN texels transparent black. u8 images are windowed too (the full-range window
/// leaves them unchanged).
Image windowToRgba8(const Image& image, const DisplayWindow& window);

/// "low,high" with gamma, for messages and overlays.
std::string describeDisplayWindow(const DisplayWindow& window);

}  // namespace tessera
