#include "format/metadata.h"

#include <algorithm>

#include <nlohmann/json.hpp>

namespace tessera::detail {

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

}  // namespace tessera::detail
