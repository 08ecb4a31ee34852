#include "brush_codec.h"

#include <fmt/format.h>

namespace tessera {

Result<void> decodeBrushFields(int blend, int mask, int mask_low, int mask_high,
                               const std::string& name, Brush& brush) {
  if (blend < 0 || blend >= kBlendModeCount || mask < 0 || mask > int(MaskSource::kSlope) ||
      mask_low < 0 || mask_low > 255 || mask_high < 0 || mask_high > 255)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: brush {} has out-of-range fields", name, brush.name));
  brush.blend = BlendMode(blend);
  brush.mask = MaskSource(mask);
  brush.mask_low = uint8_t(mask_low);
  brush.mask_high = uint8_t(mask_high);
  return {};
}

Result<Image> decodeBrushImage(uint32_t width_px, uint32_t height_px, const uint8_t* bytes,
                               size_t length, const std::string& what) {
  if (width_px == 0 || height_px == 0 || width_px > kMaxBrushSidePx ||
      height_px > kMaxBrushSidePx || length != size_t(width_px) * height_px * 4)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: image of {} bytes for {}x{} RGBA", what,
                                                 length, width_px, height_px));
  Image image(width_px, height_px, 4);
  std::copy(bytes, bytes + length, image.texels.begin());
  return image;
}

Result<void> checkInstances(std::span<const BrushInstance> instances, uint64_t brush_count,
                            const std::string& name) {
  for (size_t i = 0; i < instances.size(); ++i) {
    std::string what = fmt::format("{}: instance {} of the batch", name, i);
    TESSERA_TRY(validateInstance(instances[i], what));
    if (instances[i].brush >= brush_count)
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}: brush {} does not exist ({} brushes)", what, instances[i].brush,
                              brush_count));
  }
  return {};
}

}  // namespace tessera
