#pragma once
// The metadata block (docs/format.md, "Metadata"): a UTF-8 JSON object for humans and tools,
// and the checked reading of the few fields the program relies on. Pure: bytes or JSON in,
// structs out.

#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json_fwd.hpp>

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

/// `value` as an unsigned integer of at most `max`. The block is free-form and checked at
/// open only to be an object, so a field the program relies on is read through this: anything
/// else (a string, a negative or fractional number, a value above `max`) is kCorrupt naming
/// the file and the field and quotes the value, `a.tess: metadata "update.version" is not an
/// unsigned integer (it is "2")`. `field` is the field's dotted path from the block's top.
Result<uint64_t> metadataUnsigned(const nlohmann::json& value, const std::string& name,
                                  std::string_view field,
                                  uint64_t max = std::numeric_limits<uint64_t>::max());

/// `value` as an int (an integer without fraction or exponent, in int's range); kCorrupt
/// naming the file and the field otherwise, like metadataUnsigned.
Result<int> metadataInt(const nlohmann::json& value, const std::string& name,
                        std::string_view field);

/// The record `tessera update` and `append` keep in the block's "update" object
/// (docs/update.md): an archive without one was never updated in place.
struct UpdateRecord {
  bool recorded = false;    ///< "update" holds a "version"
  uint64_t version = 1;     ///< versions the file holds; 1 when not recorded
  uint64_t dead_bytes = 0;  ///< bytes of earlier versions that nothing references
};

/// Reads the "update" record of `metadata` (a JSON object). An "update" that is not an
/// object, or a "version" or "dead_bytes" that is not an unsigned integer, is kCorrupt naming
/// `name` and the field.
Result<UpdateRecord> parseUpdateRecord(const nlohmann::json& metadata, const std::string& name);

}  // namespace tessera::detail
