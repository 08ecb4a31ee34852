// Mosaic manifests (docs/builder.md, "Mosaic manifests"): the JSON document and its schema.
#include "mosaic_manifest.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <initializer_list>
#include <string_view>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <tessera/format.h>

#include "file_reader.h"

namespace tessera::detail {
namespace {

/// "line:column" of byte `offset` of `text`, both from 1, for syntax errors.
std::string lineColumn(std::string_view text, size_t offset) {
  size_t line = 1, column = 1;
  for (size_t i = 0; i < offset && i < text.size(); ++i) {
    if (text[i] == '\n') {
      ++line;
      column = 1;
    } else {
      ++column;
    }
  }
  return fmt::format("{}:{}", line, column);
}

Result<std::string> readManifestText(const std::string& path) {
  TESSERA_ASSIGN_OR_RETURN(uint64_t size, checkSourceFile(path));
  if (size > kMaxManifestBytes)
    return fail(ErrorCode::kTooLarge, fmt::format("{}: manifest of {} bytes, over the limit of {}",
                                                  path, size, kMaxManifestBytes));
  std::FILE* file = std::fopen(path.c_str(), "rb");
  if (!file)
    return fail(ErrorCode::kIo, fmt::format("{}: cannot open: {}", path, std::strerror(errno)));
  std::string text(size, '\0');
  const size_t got = std::fread(text.data(), 1, text.size(), file);
  std::fclose(file);
  if (got != size) return fail(ErrorCode::kIo, fmt::format("{}: short read", path));
  return text;
}

/// Fails naming `where` and the first key of `object` not in `known`.
Result<void> checkKeys(const nlohmann::json& object, std::initializer_list<std::string_view> known,
                       const std::string& where) {
  for (const auto& [key, value] : object.items()) {
    bool found = false;
    for (std::string_view name : known) found = found || key == name;
    if (!found) {
      std::string list;
      for (std::string_view name : known)
        list += fmt::format("{}\"{}\"", list.empty() ? "" : ", ", name);
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: unknown key \"{}\" (known: {})", where, key, list));
    }
  }
  return {};
}

/// A whole number of pixels 0..kMaxImageSidePx at `object[key]`; `value` is left alone when the
/// key is absent and `required` is false.
Result<void> readPixels(const nlohmann::json& object, const char* key, bool required,
                        const std::string& where, uint32_t& value) {
  const auto it = object.find(key);
  if (it == object.end()) {
    if (!required) return {};
    return fail(ErrorCode::kCorrupt, fmt::format("{}: \"{}\" missing", where, key));
  }
  if (!it->is_number_unsigned())
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: \"{}\" is {}, want a whole number of pixels >= 0", where, key,
                            it->dump()));
  const uint64_t number = it->get<uint64_t>();
  if (number > kMaxImageSidePx)
    return fail(ErrorCode::kTooLarge, fmt::format("{}: \"{}\" is {}, over the limit of {} px",
                                                  where, key, number, kMaxImageSidePx));
  value = uint32_t(number);
  return {};
}

Result<MosaicImage> readImage(const MosaicManifest& manifest, const nlohmann::json& entry,
                              size_t index) {
  const std::string where = fmt::format("{}: images[{}]", manifest.path, index);
  if (!entry.is_object())
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: want an object with \"path\", \"x\" and \"y\"", where));
  TESSERA_TRY(checkKeys(entry, {"path", "x", "y", "width", "height"}, where));
  MosaicImage image;
  const auto path = entry.find("path");
  if (path == entry.end() || !path->is_string() || path->get<std::string>().empty())
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: \"path\" missing or not a non-empty string", where));
  image.path_text = path->get<std::string>();
  const std::filesystem::path file(image.path_text);
  image.path = file.is_absolute()
                   ? image.path_text
                   : (std::filesystem::path(manifest.path).parent_path() / file).string();
  const std::string named = fmt::format("{} ({})", where, image.path_text);
  TESSERA_TRY(readPixels(entry, "x", true, named, image.x_px));
  TESSERA_TRY(readPixels(entry, "y", true, named, image.y_px));
  TESSERA_TRY(readPixels(entry, "width", false, named, image.width_px));
  TESSERA_TRY(readPixels(entry, "height", false, named, image.height_px));
  if ((entry.contains("width") && image.width_px == 0) ||
      (entry.contains("height") && image.height_px == 0))
    return fail(ErrorCode::kCorrupt, named + ": a stated width or height must be >= 1");
  return image;
}

Result<void> readCanvas(const nlohmann::json& document, MosaicManifest& manifest) {
  TESSERA_TRY(readPixels(document, "width", false, manifest.path, manifest.width_px));
  TESSERA_TRY(readPixels(document, "height", false, manifest.path, manifest.height_px));
  if ((document.contains("width") && manifest.width_px == 0) ||
      (document.contains("height") && manifest.height_px == 0))
    return fail(ErrorCode::kCorrupt,
                manifest.path + ": a stated canvas width or height must be >= 1");
  const auto background = document.find("background");
  if (background == document.end()) return {};
  if (!background->is_array() || background->empty() || background->size() > 4)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: \"background\" is {}, want 1 to 4 numbers, one per channel",
                            manifest.path, background->dump()));
  for (const nlohmann::json& value : *background) {
    if (!value.is_number())
      return fail(ErrorCode::kCorrupt, fmt::format("{}: \"background\" holds {}, want numbers",
                                                   manifest.path, value.dump()));
    manifest.background.push_back(value.get<double>());
  }
  return {};
}

}  // namespace

std::string MosaicManifest::where(size_t index) const {
  return fmt::format("{}: images[{}] ({})", path, index, images[index].path_text);
}

bool looksLikeManifest(const uint8_t* bytes, size_t size) {
  size_t at = 0;
  if (size >= 3 && bytes[0] == 0xef && bytes[1] == 0xbb && bytes[2] == 0xbf) at = 3;
  while (at < size &&
         (bytes[at] == ' ' || bytes[at] == '\t' || bytes[at] == '\n' || bytes[at] == '\r'))
    ++at;
  return at < size && bytes[at] == '{';
}

Result<MosaicManifest> readMosaicManifest(const std::string& path) {
  TESSERA_ASSIGN_OR_RETURN(std::string text, readManifestText(path));
  nlohmann::json document;
  try {
    document = nlohmann::json::parse(text);
  } catch (const nlohmann::json::parse_error& e) {
    // what() repeats the position after a library prefix: keep only the problem.
    std::string_view problem = e.what();
    if (const size_t column = problem.find(", column "); column != std::string_view::npos)
      if (const size_t colon = problem.find(": ", column); colon != std::string_view::npos)
        problem.remove_prefix(colon + 2);
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}:{}: bad JSON: {}", path,
                            lineColumn(text, e.byte > 0 ? e.byte - 1 : 0), problem));
  } catch (const nlohmann::json::exception& e) {
    // Valid syntax the parser still refuses: a number beyond a double (1e999).
    return fail(ErrorCode::kCorrupt, fmt::format("{}: bad JSON: {}", path, e.what()));
  }
  MosaicManifest manifest;
  manifest.path = path;
  if (!document.is_object())
    return fail(ErrorCode::kCorrupt, path + ": a mosaic manifest is a JSON object with \"images\"");
  TESSERA_TRY(checkKeys(document, {"width", "height", "background", "images"}, path));
  TESSERA_TRY(readCanvas(document, manifest));
  const auto images = document.find("images");
  if (images == document.end() || !images->is_array() || images->empty())
    return fail(ErrorCode::kCorrupt,
                path + ": \"images\" missing or not a non-empty array of {\"path\", \"x\", \"y\"}");
  if (images->size() > kMaxMosaicImages)
    return fail(ErrorCode::kTooLarge, fmt::format("{}: {} images, over the limit of {}", path,
                                                  images->size(), kMaxMosaicImages));
  manifest.images.reserve(images->size());
  for (size_t i = 0; i < images->size(); ++i) {
    TESSERA_ASSIGN_OR_RETURN(MosaicImage image, readImage(manifest, (*images)[i], i));
    manifest.images.push_back(std::move(image));
  }
  return manifest;
}

}  // namespace tessera::detail
