#pragma once
// The ptm codec's two entry points, one per library (docs/codecs.md, "ptm (6)").

#include <cstdint>
#include <span>
#include <vector>

#include "codecs/encode.h"

namespace tessera::detail {

/// Decode side (tessera::codecs): decodes any ptm payload; `parent` is required unless the
/// payload is coded without one (the coarsest level). The contract of DecodeFunction.
Result<void> decodePtm(std::span<const uint8_t> payload, Image& out, const ParentTexels* parent,
                       CodecScratch* scratch);
/// Encode side (tessera::encoders): `options.effort` picks the predictor and coder rule
/// (docs/codecs.md, "ptm (6)"). The contract of EncodeFunction.
Result<std::vector<uint8_t>> encodePtmForEffort(const ImageView& tile, const EncodeOptions& options,
                                                const ParentTexels* parent, CodecScratch* scratch);

}  // namespace tessera::detail
