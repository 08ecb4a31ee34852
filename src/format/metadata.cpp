#include "format/metadata.h"

#include <algorithm>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

namespace tessera::detail {

namespace {

/// A value as an error message quotes it: JSON, ASCII, cut at 40 characters.
std::string shown(const nlohmann::json& value) {
  return value.dump(-1, ' ', /*ensure_ascii=*/true).substr(0, 40);
}

}  // namespace

Result<ArchiveMetadata> parseMetadata(std::span<const uint8_t> bytes, size_t image_count,
                                      const std::string& name) {
  // nlohmann's lexer ends the document at a NUL byte, so a block with one would be accepted
  // with whatever follows it unread; JSON text never holds a raw NUL.
  if (std::find(bytes.begin(), bytes.end(), uint8_t(0)) != bytes.end())
    return fail(ErrorCode::kCorrupt, name + ": metadata holds a NUL byte");
  const nlohmann::json parsed =
      nlohmann::json::parse(bytes.begin(), bytes.end(), nullptr, /*allow_exceptions=*/false);
  if (parsed.is_discarded() || !parsed.is_object())
    return fail(ErrorCode::kCorrupt, name + ": metadata is not a JSON object");
  ArchiveMetadata metadata;
  metadata.json.assign(bytes.begin(), bytes.end());
  metadata.image_names.resize(image_count);
  const auto images = parsed.find("images");
  if (images == parsed.end() || !images->is_array()) return metadata;
  for (size_t i = 0; i < image_count && i < images->size(); ++i) {
    const nlohmann::json& image = (*images)[i];
    if (!image.is_object()) continue;
    const auto image_name = image.find("name");
    if (image_name != image.end() && image_name->is_string())
      metadata.image_names[i] = image_name->get<std::string>();
  }
  return metadata;
}

Result<uint64_t> metadataUnsigned(const nlohmann::json& value, const std::string& name,
                                  std::string_view field, uint64_t max) {
  // An integer: parsed without a fraction or exponent (larger than 2^64 - 1 parses as a double
  // and is refused too); signed when parsed with a minus or built from a C++ int.
  const bool unsigned_integer =
      value.is_number_unsigned() || (value.is_number_integer() && value.get<int64_t>() >= 0);
  if (!unsigned_integer)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: metadata \"{}\" is not an unsigned integer (it is {})", name,
                            field, shown(value)));
  const uint64_t number = value.get<uint64_t>();
  if (number > max)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: metadata \"{}\" is {}, above {}", name, field, number, max));
  return number;
}

Result<int> metadataInt(const nlohmann::json& value, const std::string& name,
                        std::string_view field) {
  const bool fits = value.is_number_unsigned()
                        ? value.get<uint64_t>() <= uint64_t(std::numeric_limits<int>::max())
                        : value.is_number_integer() &&
                              value.get<int64_t>() >= std::numeric_limits<int>::min() &&
                              value.get<int64_t>() <= std::numeric_limits<int>::max();
  if (!fits)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: metadata \"{}\" is not an integer (it is {})",
                                                 name, field, shown(value)));
  return value.get<int>();
}

Result<UpdateRecord> parseUpdateRecord(const nlohmann::json& metadata, const std::string& name) {
  UpdateRecord record;
  const auto update = metadata.find("update");
  if (update == metadata.end()) return record;
  if (!update->is_object())
    return fail(ErrorCode::kCorrupt, name + ": metadata \"update\" is not an object");
  if (const auto version = update->find("version"); version != update->end()) {
    TESSERA_ASSIGN_OR_RETURN(record.version, metadataUnsigned(*version, name, "update.version"));
    record.recorded = true;
  }
  if (const auto dead = update->find("dead_bytes"); dead != update->end()) {
    TESSERA_ASSIGN_OR_RETURN(record.dead_bytes, metadataUnsigned(*dead, name, "update.dead_bytes"));
  }
  return record;
}

}  // namespace tessera::detail
