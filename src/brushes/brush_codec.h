#pragma once
// Row <-> struct rules the two backends share, so that they accept and return the same data.

#include <cstdint>
#include <span>
#include <string>

#include <tessera/procedural.h>
#include <tessera/result.h>

namespace tessera {

/// Checks stored brush fields and fills `brush`; kCorrupt naming `name` when out of range.
Result<void> decodeBrushFields(int blend, int mask, int mask_low, int mask_high,
                               const std::string& name, Brush& brush);
/// An image from its stored RGBA bytes; kCorrupt when the size disagrees.
Result<Image> decodeBrushImage(uint32_t width_px, uint32_t height_px, const uint8_t* bytes,
                               size_t length, const std::string& what);
/// validateInstance on each, and brush ids below `brush_count`; the message names the
/// instance's position in the batch.
Result<void> checkInstances(std::span<const BrushInstance> instances, uint64_t brush_count,
                            const std::string& name);

}  // namespace tessera
