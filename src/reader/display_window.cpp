// The window/level mapping of wide samples to 8 bits, and the windows an archive resolves to.
#include <tessera/display_window.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

namespace tessera {

namespace {

bool parseNumber(std::string_view text, double& value) {
  const char* end = text.data() + text.size();
  auto [ptr, ec] = std::from_chars(text.data(), end, value);
  return ec == std::errc() && ptr == end && std::isfinite(value);
}

Result<void> windowError(std::string_view text, std::string_view problem) {
  return fail(ErrorCode::kInvalidArgument, fmt::format("window '{}': {}", text, problem));
}

double sampleAt(const Image& image, size_t index) {
  if (image.sample_type == SampleType::kU8) return image.texels[index];
  if (image.sample_type == SampleType::kU16) {
    uint16_t sample;
    std::memcpy(&sample, image.texels.data() + index * 2, 2);
    return sample;
  }
  float sample;
  std::memcpy(&sample, image.texels.data() + index * 4, 4);
  return sample;
}

uint32_t colourChannels(uint32_t channels) {
  return channels == 2 || channels == 4 ? channels - 1 : channels;
}

// Colour channels' lowest "min" and highest "max" of the image's statistics, if both exist.
bool statisticsRange(const Archive& archive, uint32_t image, double& low, double& high) {
  const nlohmann::json meta = nlohmann::json::parse(archive.metadataJson(), nullptr, false);
  if (!meta.is_object() || !meta.contains("images") || !meta["images"].is_array() ||
      image >= meta["images"].size())
    return false;
  // Free-form metadata: an entry of another type is as good as none (the window then comes
  // from the pixels).
  const nlohmann::json& entry = meta["images"][image];
  if (!entry.is_object()) return false;
  const nlohmann::json stats = entry.value("statistics", nlohmann::json());
  if (!stats.is_object() || !stats.contains("min") || !stats.contains("max")) return false;
  const nlohmann::json &mins = stats["min"], &maxes = stats["max"];
  if (!mins.is_array() || !maxes.is_array()) return false;
  const uint32_t colours = colourChannels(archive.images()[image].channels);
  low = INFINITY;
  high = -INFINITY;
  for (uint32_t c = 0; c < colours && c < mins.size() && c < maxes.size(); ++c) {
    if (mins[c].is_number()) low = std::min(low, mins[c].get<double>());
    if (maxes[c].is_number()) high = std::max(high, maxes[c].get<double>());
  }
  return std::isfinite(low) && std::isfinite(high);
}

// Percentiles `first` and `second` of the finite colour samples of a coarse level.
Result<DisplayWindow> percentileWindow(const Archive& archive, uint32_t image, double first,
                                       double second) {
  const ImageInfo& info = archive.images()[image];
  uint32_t level = 0;
  while (level + 1 < info.level_count &&
         uint64_t(info.levelWidthPx(level)) * info.levelHeightPx(level) > 512u * 512u)
    ++level;
  Result<Image> region = archive.readRegion(
      image, level, PixelRect{0, 0, info.levelWidthPx(level), info.levelHeightPx(level)});
  if (!region) return forwardError(region);
  const uint32_t colours = colourChannels(info.channels);
  std::vector<double> values;
  const size_t texels = size_t(region->width_px) * region->height_px;
  values.reserve(texels * colours);
  for (size_t t = 0; t < texels; ++t)
    for (uint32_t c = 0; c < colours; ++c) {
      const double v = sampleAt(*region, t * info.channels + c);
      if (std::isfinite(v)) values.push_back(v);
    }
  if (values.empty()) return fullRangeWindow(info.sample_type);
  auto at = [&](double percentile) {
    const size_t k = size_t(std::llround(percentile / 100.0 * double(values.size() - 1)));
    std::nth_element(values.begin(), values.begin() + ptrdiff_t(k), values.end());
    return values[k];
  };
  DisplayWindow window;
  window.low = at(first);
  window.high = at(second);
  return window;
}

}  // namespace

Result<void> parseDisplayWindow(std::string_view text, DisplayWindowRequest& request) {
  if (text == "auto") {
    request.kind = DisplayWindowRequest::Kind::kAuto;
    return {};
  }
  const size_t comma = text.find(',');
  if (comma == std::string_view::npos)
    return windowError(text, "expected MIN,MAX, pLOW,pHIGH or auto");
  std::string_view a = text.substr(0, comma), b = text.substr(comma + 1);
  const bool percentiles = !a.empty() && a[0] == 'p';
  if (percentiles != (!b.empty() && b[0] == 'p'))
    return windowError(text, "both ends are values or both are percentiles (p1,p99)");
  if (percentiles) {
    a.remove_prefix(1);
    b.remove_prefix(1);
  }
  double first = 0, second = 0;
  if (!parseNumber(a, first) || !parseNumber(b, second))
    return windowError(text, "the ends must be finite numbers");
  if (first >= second) return windowError(text, "the low end must be below the high end");
  if (percentiles && (first < 0 || second > 100))
    return windowError(text, "percentiles lie between 0 and 100");
  request.kind =
      percentiles ? DisplayWindowRequest::Kind::kPercentiles : DisplayWindowRequest::Kind::kValues;
  request.first = first;
  request.second = second;
  return {};
}

Result<double> parseGamma(std::string_view text) {
  double gamma = 0;
  if (!parseNumber(text, gamma) || gamma <= 0)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("gamma '{}': expected a number above 0", text));
  return gamma;
}

DisplayWindow fullRangeWindow(SampleType type) {
  switch (type) {
    case SampleType::kU16: return {0, 65535, 1};
    case SampleType::kF32: return {0, 1, 1};
    default: return {0, 255, 1};
  }
}

Result<DisplayWindow> resolveDisplayWindow(const Archive& archive, uint32_t image,
                                           const DisplayWindowRequest& request) {
  if (image >= archive.images().size())
    return fail(ErrorCode::kInvalidArgument, fmt::format("{}: no image {}", archive.name(), image));
  const SampleType type = archive.images()[image].sample_type;
  DisplayWindow window = fullRangeWindow(type);
  if (request.kind == DisplayWindowRequest::Kind::kValues) {
    window.low = request.first;
    window.high = request.second;
  } else if (request.kind == DisplayWindowRequest::Kind::kPercentiles) {
    TESSERA_ASSIGN_OR_RETURN(window,
                             percentileWindow(archive, image, request.first, request.second));
  } else if (type != SampleType::kU8 && !statisticsRange(archive, image, window.low, window.high)) {
    TESSERA_ASSIGN_OR_RETURN(window, percentileWindow(archive, image, 1, 99));
  }
  if (window.high <= window.low)
    window.high =
        window.low + (type == SampleType::kF32 ? std::max(1e-6, std::abs(window.low) * 1e-6) : 1.0);
  window.gamma = request.gamma;
  return window;
}

uint8_t windowSample(double value, const DisplayWindow& window) {
  if (std::isnan(value)) return 0;
  double t = std::clamp((value - window.low) / (window.high - window.low), 0.0, 1.0);
  if (window.gamma != 1) t = std::pow(t, window.gamma);
  return uint8_t(std::floor(t * 255 + 0.5));
}

Image windowToRgba8(const Image& image, const DisplayWindow& window) {
  Image out(image.width_px, image.height_px, 4);
  const uint32_t channels = image.channels;
  const bool has_alpha = channels == 2 || channels == 4;
  const uint32_t colours = colourChannels(channels);
  const double alpha_scale = image.sample_type == SampleType::kU16  ? 1.0 / 65535
                             : image.sample_type == SampleType::kU8 ? 1.0 / 255
                                                                    : 1.0;
  const size_t texels = size_t(image.width_px) * image.height_px;
  for (size_t t = 0; t < texels; ++t) {
    uint8_t* rgba = out.texels.data() + t * 4;
    bool no_data = false;
    uint8_t colour[3] = {0, 0, 0};
    for (uint32_t c = 0; c < colours; ++c) {
      const double v = sampleAt(image, t * channels + c);
      no_data = no_data || std::isnan(v);
      colour[c] = windowSample(v, window);
    }
    double alpha = 1;
    if (has_alpha) alpha = sampleAt(image, t * channels + colours) * alpha_scale;
    if (no_data || std::isnan(alpha)) {
      std::memset(rgba, 0, 4);
      continue;
    }
    for (uint32_t c = 0; c < 3; ++c) rgba[c] = colours == 1 ? colour[0] : colour[c];
    rgba[3] = uint8_t(std::floor(std::clamp(alpha, 0.0, 1.0) * 255 + 0.5));
  }
  return out;
}

std::string describeDisplayWindow(const DisplayWindow& window) {
  return fmt::format("window {:g},{:g} gamma {:g}", window.low, window.high, window.gamma);
}

}  // namespace tessera
