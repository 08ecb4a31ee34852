#pragma once
// Little-endian field access for the on-disk structures (docs/format.md: all integers are
// little-endian). Bounds are the caller's job: every decoder checks the span size first.

#include <bit>
#include <cstdint>
#include <cstring>
#include <span>
#include <vector>

namespace tessera::detail {

inline uint16_t loadU16(const uint8_t* p) {
  return uint16_t(p[0] | (p[1] << 8));
}
inline uint32_t loadU32(const uint8_t* p) {
  return uint32_t(p[0]) | (uint32_t(p[1]) << 8) | (uint32_t(p[2]) << 16) | (uint32_t(p[3]) << 24);
}
inline uint64_t loadU64(const uint8_t* p) {
  return uint64_t(loadU32(p)) | (uint64_t(loadU32(p + 4)) << 32);
}

inline void storeU16(uint8_t* p, uint16_t v) {
  p[0] = uint8_t(v);
  p[1] = uint8_t(v >> 8);
}
inline void storeU32(uint8_t* p, uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = uint8_t(v >> (8 * i));
}
inline void storeU64(uint8_t* p, uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = uint8_t(v >> (8 * i));
}
/// IEEE 754 binary32, little-endian.
inline void storeF32(uint8_t* p, float v) {
  storeU32(p, std::bit_cast<uint32_t>(v));
}
inline float loadF32(const uint8_t* p) {
  return std::bit_cast<float>(loadU32(p));
}
inline void appendU32(std::vector<uint8_t>& out, uint32_t v) {
  for (int i = 0; i < 4; ++i) out.push_back(uint8_t(v >> (8 * i)));
}

/// True when every byte is zero: reserved fields must be zero in v1.
inline bool allZero(const uint8_t* p, size_t n) {
  for (size_t i = 0; i < n; ++i)
    if (p[i]) return false;
  return true;
}

}  // namespace tessera::detail
