#pragma once
// The ptm codec's two entry points, one per library (docs/codecs.md, "ptm (6)").

#include <cstdint>
#include <span>
#include <vector>

#include "codecs/encode.h"

namespace tessera::detail {

/// Decode side (tessera::codecs): decodes a ptm payload of format 1.0; `parent` is required
/// unless the payload is coded without one (the coarsest level). A payload of a variant format
/// 1.0 removed is kUnsupported, naming it. The contract of DecodeFunction.
Result<void> decodePtm(std::span<const uint8_t> payload, Image& out, const ParentTexels* parent,
                       CodecScratch* scratch);
/// Encode side (tessera::encoders): `options.effort` picks the mode, 1 or 2, and any other value
/// the default (docs/codecs.md, "ptm (6)", "Efforts"). The contract of EncodeFunction.
Result<std::vector<uint8_t>> encodePtmForEffort(const ImageView& tile, const EncodeOptions& options,
                                                const ParentTexels* parent, CodecScratch* scratch);

}  // namespace tessera::detail
