#pragma once
// The metadata block (docs/format.md, "Metadata"): a UTF-8 JSON object for humans and tools.
// Pure: bytes in, struct out.

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <tessera/result.h>

namespace tessera::detail {

/// What a reader takes from the metadata block.
struct ArchiveMetadata {
  std::string json = "{}";               ///< the block as stored, "{}" when the file has none
  std::vector<std::string> image_names;  ///< "images"[i]."name", "" where absent or not a string
};

/// Parses the block: it must be one JSON object (kCorrupt otherwise, `name` prefixing the
/// message). Names are taken for at most `image_count` images.
Result<ArchiveMetadata> parseMetadata(std::span<const uint8_t> bytes, size_t image_count,
                                      const std::string& name);

}  // namespace tessera::detail
