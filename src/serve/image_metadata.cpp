#include "serve/image_metadata.h"

#include <nlohmann/json.hpp>

namespace tessera::detail {

std::string imageGeoreferenceJson(const Archive& archive, uint32_t image) {
  // The archive checked at open that its metadata is one JSON object; the rest is not checked
  // (it is free-form), so every step is tested here.
  const nlohmann::json metadata = nlohmann::json::parse(archive.metadataJson(), nullptr, false);
  if (!metadata.is_object()) return {};
  const auto images = metadata.find("images");
  if (images == metadata.end() || !images->is_array() || image >= images->size()) return {};
  const nlohmann::json& entry = (*images)[image];
  if (!entry.is_object()) return {};
  const auto geo = entry.find("georeference");
  if (geo == entry.end() || !geo->is_object()) return {};
  return geo->dump();
}

}  // namespace tessera::detail
