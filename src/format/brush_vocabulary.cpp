// The procedural vocabulary of tessera/procedural.h that is plain data: names, bounds, checks.
#include <tessera/procedural.h>

#include <cmath>

#include <fmt/format.h>

namespace tessera {

namespace {

constexpr const char* kBlendNames[kBlendModeCount] = {"normal", "multiply", "add", "overlay"};
constexpr const char* kMaskNames[3] = {"none", "height", "slope"};

}  // namespace

const char* blendModeName(BlendMode mode) {
  return uint8_t(mode) < kBlendModeCount ? kBlendNames[uint8_t(mode)] : "unknown";
}

bool parseBlendModeName(std::string_view name, BlendMode* mode) {
  for (uint8_t i = 0; i < kBlendModeCount; ++i) {
    if (name == kBlendNames[i]) {
      *mode = BlendMode(i);
      return true;
    }
  }
  return false;
}

const char* maskSourceName(MaskSource source) {
  return uint8_t(source) < 3 ? kMaskNames[uint8_t(source)] : "unknown";
}

bool parseMaskSourceName(std::string_view name, MaskSource* source) {
  for (uint8_t i = 0; i < 3; ++i) {
    if (name == kMaskNames[i]) {
      *source = MaskSource(i);
      return true;
    }
  }
  return false;
}

BoxPx instanceBounds(const BrushInstance& instance) {
  // sqrt(2) rounded up, so the box contains the circle around any rotated rectangle whose
  // longer half side is radius * scale.
  double half = double(instance.radius_px) * double(instance.scale) * 1.4142136;
  return {instance.x_px - half, instance.y_px - half, instance.x_px + half, instance.y_px + half};
}

Result<void> validateInstance(const BrushInstance& instance, const std::string& what) {
  if (!std::isfinite(instance.x_px) || !std::isfinite(instance.y_px))
    return fail(ErrorCode::kInvalidArgument, what + ": position is not finite");
  if (!std::isfinite(instance.radius_px) || !(instance.radius_px > 0))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: radius {} is not a positive number", what, instance.radius_px));
  if (!std::isfinite(instance.scale) || !(instance.scale > 0))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: scale {} is not a positive number", what, instance.scale));
  if (!std::isfinite(instance.rotation_rad))
    return fail(ErrorCode::kInvalidArgument, what + ": rotation is not finite");
  double extent = double(instance.radius_px) * instance.scale;
  if (extent > 1e8 || std::abs(instance.x_px) > 1e9 || std::abs(instance.y_px) > 1e9)
    return fail(ErrorCode::kInvalidArgument,
                what + ": position or extent beyond 1e9 texels (no texture is that large)");
  return {};
}

Result<void> validateBrush(const Brush& brush, const std::string& what) {
  if (brush.images.empty() || brush.images.size() > kMaxBrushImages)
    return fail(ErrorCode::kInvalidArgument, fmt::format("{}: {} images (1..{} allowed)", what,
                                                         brush.images.size(), kMaxBrushImages));
  if (uint8_t(brush.blend) >= kBlendModeCount || uint8_t(brush.mask) > 2)
    return fail(ErrorCode::kInvalidArgument, what + ": unknown blend mode or mask source");
  for (size_t i = 0; i < brush.images.size(); ++i) {
    const Image& image = brush.images[i];
    if (image.channels != 4)
      return fail(
          ErrorCode::kInvalidArgument,
          fmt::format("{}: image {} has {} channels, brushes are RGBA", what, i, image.channels));
    if (image.width_px == 0 || image.height_px == 0 || image.width_px > kMaxBrushSidePx ||
        image.height_px > kMaxBrushSidePx)
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}: image {} is {}x{}, sides must be 1..{}", what, i, image.width_px,
                              image.height_px, kMaxBrushSidePx));
    if (image.texels.size() != size_t(image.width_px) * image.height_px * 4)
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}: image {} holds {} bytes for {}x{} RGBA", what, i,
                              image.texels.size(), image.width_px, image.height_px));
  }
  return {};
}

}  // namespace tessera
