#include "format/checksum.h"

#include <xxhash.h>

namespace tessera::detail {

uint64_t checksum64(std::span<const uint8_t> bytes) {
  return XXH3_64bits(bytes.data(), bytes.size());
}

}  // namespace tessera::detail
