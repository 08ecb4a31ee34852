#pragma once
// JPEG through TurboJPEG, alpha as a zstd plane after it (docs/codecs.md, "jpeg"): the codec's two
// entry points, one per library.

#include <cstdint>
#include <span>
#include <vector>

#include "codecs/encode.h"

namespace tessera::detail {

/// Decode side (tessera::codecs): the contract of DecodeFunction (codecs/decode.h).
Result<void> decodeJpeg(std::span<const uint8_t> payload, Image& out, const ParentTexels* parent,
                        CodecScratch* scratch);
/// Encode side (tessera::encoders): the contract of EncodeFunction (codecs/encode.h).
Result<std::vector<uint8_t>> encodeJpeg(const ImageView& tile, const EncodeOptions& options,
                                        const ParentTexels* parent, CodecScratch* scratch);

}  // namespace tessera::detail
