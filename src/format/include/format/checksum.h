#pragma once
// Checksums of payloads, directory pages, the root directory and the header: XXH3-64
// (docs/format.md, "Checksums"), chosen for speed (tens of GB/s) over CRC32C.

#include <cstdint>
#include <span>

namespace tessera::detail {

/// XXH3-64 with seed 0.
uint64_t checksum64(std::span<const uint8_t> bytes);

}  // namespace tessera::detail
