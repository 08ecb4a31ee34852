// Instance lists in CSV, JSON and GeoJSON (docs/procedural.md, "Importing instances"): parsed
// whole and checked before anything is written, then added in one transaction.
#include <tessera/brushes.h>

#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

namespace tessera {

namespace {

constexpr double kDegreesToRadians = 3.14159265358979323846 / 180;

using BrushIds = std::function<bool(std::string_view, uint32_t*)>;

/// One field's text and where it came from, for messages.
struct Field {
  std::string_view name;
  std::string text;
};

Result<double> parseNumber(const std::string& text, const std::string& where,
                           std::string_view field) {
  double value = 0;
  auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (ec != std::errc() || end != text.data() + text.size() || !std::isfinite(value))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: {}: '{}' is not a number", where, field, text));
  return value;
}

Result<uint32_t> parseTint(const std::string& text, const std::string& where) {
  std::string_view hex = text;
  if (!hex.empty() && hex[0] == '#') hex.remove_prefix(1);
  uint32_t value = 0;
  auto [end, ec] = std::from_chars(hex.data(), hex.data() + hex.size(), value, 16);
  if ((hex.size() != 6 && hex.size() != 8) || ec != std::errc() || end != hex.data() + hex.size())
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: tint: '{}' is not #RRGGBB or #RRGGBBAA", where, text));
  if (hex.size() == 6) value = (value << 8) | 0xFF;
  // Text is R G B A from the left; the struct keeps channel c in byte c.
  return ((value >> 24) & 0xFF) | ((value >> 8) & 0xFF00) | ((value << 8) & 0xFF0000) |
         ((value & 0xFF) << 24);
}

/// Sets one named field of `instance` from its text; unknown names are an error.
Result<void> setField(BrushInstance& instance, std::string_view name, const std::string& text,
                      const std::string& where, const BrushIds& brush_ids) {
  if (name == "brush") {
    if (!brush_ids(text, &instance.brush))
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}: brush: no brush '{}'", where, text));
    return {};
  }
  if (name == "tint") {
    TESSERA_ASSIGN_OR_RETURN(instance.tint_rgba, parseTint(text, where));
    return {};
  }
  TESSERA_ASSIGN_OR_RETURN(double value, parseNumber(text, where, name));
  auto integer_in = [&](double low, double high) -> Result<void> {
    if (value != std::floor(value) || value < low || value > high)
      return fail(ErrorCode::kInvalidArgument, fmt::format("{}: {}: {} is not an integer in {}..{}",
                                                           where, name, text, low, high));
    return {};
  };
  if (name == "x") {
    instance.x_px = value;
  } else if (name == "y") {
    instance.y_px = value;
  } else if (name == "radius") {
    if (!(value > 0))
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}: radius: {} is not positive", where, text));
    instance.radius_px = float(value);
  } else if (name == "rotation") {
    instance.rotation_rad = float(value * kDegreesToRadians);
  } else if (name == "scale") {
    if (!(value > 0))
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}: scale: {} is not positive", where, text));
    instance.scale = float(value);
  } else if (name == "opacity") {
    if (value < 0 || value > 1)
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}: opacity: {} is outside 0..1", where, text));
    instance.opacity = uint8_t(std::lround(value * 255));
  } else if (name == "layer") {
    TESSERA_TRY(integer_in(-2147483648.0, 2147483647.0));
    instance.layer = int32_t(value);
  } else if (name == "variant") {
    TESSERA_TRY(integer_in(0, 255));
    instance.variant = uint8_t(value);
  } else {
    return fail(ErrorCode::kInvalidArgument, fmt::format("{}: unknown field '{}'", where, name));
  }
  return {};
}

// Splits one CSV line (RFC 4180 quotes, no embedded newlines).
Result<std::vector<std::string>> splitCsv(std::string_view line, const std::string& where) {
  std::vector<std::string> fields(1);
  bool quoted = false;
  for (size_t i = 0; i < line.size(); ++i) {
    char c = line[i];
    if (quoted) {
      if (c == '"' && i + 1 < line.size() && line[i + 1] == '"') {
        fields.back() += '"';
        ++i;
      } else if (c == '"') {
        quoted = false;
      } else {
        fields.back() += c;
      }
    } else if (c == '"') {
      quoted = true;
    } else if (c == ',') {
      fields.emplace_back();
    } else if (c != '\r') {
      fields.back() += c;
    }
  }
  if (quoted) return fail(ErrorCode::kInvalidArgument, where + ": unterminated quote");
  for (std::string& field : fields) {
    size_t begin = field.find_first_not_of(" \t"), end = field.find_last_not_of(" \t");
    field = begin == std::string::npos ? "" : field.substr(begin, end - begin + 1);
  }
  return fields;
}

Result<std::vector<BrushInstance>> parseCsv(std::string_view text, const std::string& name,
                                            const BrushIds& brush_ids) {
  std::vector<BrushInstance> instances;
  std::vector<std::string> header;
  size_t line_number = 0;
  size_t pos = 0;
  while (pos < text.size()) {
    size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(pos, end - pos);
    pos = end + 1;
    ++line_number;
    if (line.find_first_not_of(" \t\r") == std::string_view::npos || line[0] == '#') continue;
    std::string where = fmt::format("{}:{}", name, line_number);
    TESSERA_ASSIGN_OR_RETURN(std::vector<std::string> fields, splitCsv(line, where));
    if (header.empty()) {
      header = fields;
      for (const char* required : {"brush", "x", "y", "radius"})
        if (std::find(header.begin(), header.end(), required) == header.end())
          return fail(ErrorCode::kInvalidArgument,
                      fmt::format("{}: header lacks the column '{}'", where, required));
      continue;
    }
    if (fields.size() != header.size())
      return fail(ErrorCode::kInvalidArgument, fmt::format("{}: {} columns, the header has {}",
                                                           where, fields.size(), header.size()));
    BrushInstance instance;
    for (size_t column = 0; column < fields.size(); ++column) {
      if (fields[column].empty()) {
        if (header[column] == "brush" || header[column] == "x" || header[column] == "y" ||
            header[column] == "radius")
          return fail(ErrorCode::kInvalidArgument,
                      fmt::format("{}:{}: {}: missing", where, column + 1, header[column]));
        continue;
      }
      TESSERA_TRY(setField(instance, header[column], fields[column],
                           fmt::format("{}:{}", where, column + 1), brush_ids));
    }
    instance.id = instances.size() + 1;
    TESSERA_TRY(validateInstance(instance, where));
    instances.push_back(instance);
  }
  return instances;
}

// A JSON value as the text setField parses: numbers exactly as JSON wrote them.
Result<std::string> jsonText(const nlohmann::json& value, const std::string& where) {
  if (value.is_string()) return value.get<std::string>();
  if (value.is_number()) return value.dump();
  return fail(ErrorCode::kInvalidArgument, where + ": expected a number or a string");
}

Result<BrushInstance> instanceFromJson(const nlohmann::json& object, const std::string& where,
                                       const BrushIds& brush_ids, const nlohmann::json* point) {
  if (!object.is_object()) return fail(ErrorCode::kInvalidArgument, where + ": expected an object");
  BrushInstance instance;
  for (const char* required : {"brush", "radius"})
    if (!object.contains(required))
      return fail(ErrorCode::kInvalidArgument, fmt::format("{}: '{}' missing", where, required));
  if (!point && (!object.contains("x") || !object.contains("y")))
    return fail(ErrorCode::kInvalidArgument, where + ": 'x' and 'y' missing");
  for (const auto& [key, value] : object.items()) {
    std::string field_where = where + "/" + key;
    TESSERA_ASSIGN_OR_RETURN(std::string text, jsonText(value, field_where));
    TESSERA_TRY(setField(instance, key, text, where, brush_ids));
  }
  if (point) {
    if (!point->is_array() || point->size() < 2 || !(*point)[0].is_number() ||
        !(*point)[1].is_number())
      return fail(ErrorCode::kInvalidArgument, where + ": coordinates are not [x, y]");
    instance.x_px = (*point)[0].get<double>();
    instance.y_px = (*point)[1].get<double>();
  }
  TESSERA_TRY(validateInstance(instance, where));
  return instance;
}

// The line and column of a byte offset, for JSON syntax errors.
std::string lineColumn(std::string_view text, size_t offset) {
  offset = std::min(offset, text.size());
  size_t line = 1, column = 1;
  for (size_t i = 0; i < offset; ++i) {
    if (text[i] == '\n') {
      ++line;
      column = 1;
    } else {
      ++column;
    }
  }
  return fmt::format("{}:{}", line, column);
}

Result<std::vector<BrushInstance>> parseJson(std::string_view text, InstanceFileFormat format,
                                             const std::string& name, const BrushIds& brush_ids) {
  nlohmann::json document;
  try {
    document = nlohmann::json::parse(text);
  } catch (const nlohmann::json::parse_error& e) {
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}:{}: JSON syntax error: {}", name,
                            lineColumn(text, e.byte > 0 ? e.byte - 1 : 0), e.what()));
  } catch (const nlohmann::json::exception& e) {
    // Valid syntax the parser still refuses: a number beyond a double (1e999).
    return fail(ErrorCode::kInvalidArgument, fmt::format("{}: JSON error: {}", name, e.what()));
  }
  std::vector<BrushInstance> instances;
  if (format == InstanceFileFormat::kGeoJson) {
    if (!document.is_object() || document.value("type", "") != "FeatureCollection" ||
        !document.contains("features") || !document["features"].is_array())
      return fail(ErrorCode::kInvalidArgument, name + ": not a GeoJSON FeatureCollection");
    const auto& features = document["features"];
    for (size_t i = 0; i < features.size(); ++i) {
      std::string where = fmt::format("{}: /features/{}", name, i);
      const auto& feature = features[i];
      if (!feature.is_object() || !feature.contains("geometry") ||
          !feature["geometry"].is_object() || feature["geometry"].value("type", "") != "Point")
        return fail(ErrorCode::kInvalidArgument, where + ": not a Point feature");
      static const nlohmann::json kEmpty = nlohmann::json::object();
      const auto& properties = feature.contains("properties") ? feature["properties"] : kEmpty;
      TESSERA_ASSIGN_OR_RETURN(BrushInstance instance,
                               instanceFromJson(properties, where + "/properties", brush_ids,
                                                &feature["geometry"]["coordinates"]));
      instance.id = i + 1;
      instances.push_back(instance);
    }
    return instances;
  }
  const nlohmann::json* list = &document;
  if (document.is_object() && document.contains("instances")) list = &document["instances"];
  if (!list->is_array())
    return fail(ErrorCode::kInvalidArgument,
                name + ": expected an array of instances or {\"instances\": [...]}");
  const char* prefix = list == &document ? "" : "/instances";
  for (size_t i = 0; i < list->size(); ++i) {
    TESSERA_ASSIGN_OR_RETURN(BrushInstance instance,
                             instanceFromJson((*list)[i], fmt::format("{}: {}/{}", name, prefix, i),
                                              brush_ids, nullptr));
    instance.id = i + 1;
    instances.push_back(instance);
  }
  return instances;
}

}  // namespace

bool instanceFileFormatFor(std::string_view path, InstanceFileFormat* format) {
  auto ends = [&](std::string_view suffix) {
    return path.size() >= suffix.size() && path.substr(path.size() - suffix.size()) == suffix;
  };
  if (ends(".csv"))
    *format = InstanceFileFormat::kCsv;
  else if (ends(".geojson"))
    *format = InstanceFileFormat::kGeoJson;
  else if (ends(".json"))
    *format = InstanceFileFormat::kJson;
  else
    return false;
  return true;
}

Result<std::vector<BrushInstance>> parseInstances(std::string_view text, InstanceFileFormat format,
                                                  const std::string& name,
                                                  const BrushIds& brush_ids) {
  if (format == InstanceFileFormat::kCsv) return parseCsv(text, name, brush_ids);
  return parseJson(text, format, name, brush_ids);
}

Result<ImportReport> importInstances(BrushDatabase& database, const std::string& path) {
  InstanceFileFormat format;
  if (!instanceFileFormatFor(path, &format))
    return fail(ErrorCode::kInvalidArgument,
                path + ": unknown instance file type (expected .csv, .json or .geojson)");
  std::ifstream file(path, std::ios::binary);
  if (!file) return fail(ErrorCode::kNotFound, path + ": cannot open");
  std::stringstream contents;
  contents << file.rdbuf();
  if (file.bad()) return fail(ErrorCode::kIo, path + ": read failed");
  TESSERA_ASSIGN_OR_RETURN(std::vector<Brush> brushes, database.brushes());
  auto brush_ids = [&](std::string_view text, uint32_t* id) {
    for (uint32_t b = 0; b < brushes.size(); ++b) {
      if (brushes[b].name == text) {
        *id = b;
        return true;
      }
    }
    uint32_t value = 0;
    auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
    if (ec != std::errc() || end != text.data() + text.size() || value >= brushes.size())
      return false;
    *id = value;
    return true;
  };
  std::string text = contents.str();
  TESSERA_ASSIGN_OR_RETURN(std::vector<BrushInstance> instances,
                           parseInstances(text, format, path, brush_ids));
  TESSERA_ASSIGN_OR_RETURN(std::vector<uint64_t> ids, database.addInstances(instances));
  ImportReport report;
  report.instances = ids.size();
  if (!ids.empty()) {
    report.first_id = ids.front();
    report.last_id = ids.back();
  }
  return report;
}

}  // namespace tessera
