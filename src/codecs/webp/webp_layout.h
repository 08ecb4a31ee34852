#pragma once
// What the WebP codec's two sides share: the layout of the payload, a simple-format RIFF file
// holding one VP8L chunk (docs/codecs.md, "webp").

#include <cstddef>
#include <cstdint>

namespace tessera::detail::webp {

inline constexpr const char* kWhat = "webp payload";
/// "RIFF" size "WEBP" "VP8L" size, then the VP8L bitstream.
inline constexpr size_t kRiffHeaderBytes = 12;
inline constexpr size_t kChunkHeaderBytes = 8;
/// The VP8L header: signature 0x2F, then 14 bits width - 1, 14 bits height - 1, 1 bit
/// alpha_is_used, 3 bits version, packed LSB first; alpha_is_used is bit 4 of its 4th byte.
inline constexpr uint8_t kVp8lSignature = 0x2F;
inline constexpr size_t kAlphaHintByte = kRiffHeaderBytes + kChunkHeaderBytes + 4;
inline constexpr uint8_t kAlphaHintBit = 0x10;

}  // namespace tessera::detail::webp
