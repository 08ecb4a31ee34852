// Instance lists: CSV, JSON and GeoJSON parse to the same instances; bad rows fail with the line
// and column (CSV) or the line and column of the syntax error or the instance's path (JSON);
// an import with a bad row leaves the database untouched.
#include <tessera/brushes.h>

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "procedural/procedural_fixtures.h"

namespace tessera {
namespace {

bool brushIds(std::string_view name, uint32_t* id) {
  if (name == "rock")
    *id = 0;
  else if (name == "grass" || name == "1")
    *id = 1;
  else
    return false;
  return true;
}

std::vector<BrushInstance> parse(std::string_view text, InstanceFileFormat format) {
  auto parsed = parseInstances(text, format, "in", brushIds);
  EXPECT_TRUE(parsed) << parsed.error().message;
  return parsed ? *parsed : std::vector<BrushInstance>{};
}

std::string parseError(std::string_view text, InstanceFileFormat format) {
  auto parsed = parseInstances(text, format, "in", brushIds);
  EXPECT_FALSE(parsed);
  return parsed ? "" : parsed.error().message;
}

TEST(InstanceImport, TheThreeFormatsAgree) {
  const char* csv =
      "# a comment\n"
      "brush,x,y,radius,rotation,scale,opacity,tint,layer,variant\n"
      "rock,10.5,20,4,90,1.5,0.5,#FF800040,3,2\n"
      "grass, 1, 2, 3,,,,,,\n";
  const char* json = R"({"instances": [
      {"brush": "rock", "x": 10.5, "y": 20, "radius": 4, "rotation": 90, "scale": 1.5,
       "opacity": 0.5, "tint": "#FF800040", "layer": 3, "variant": 2},
      {"brush": "grass", "x": 1, "y": 2, "radius": 3}]})";
  const char* geojson = R"({"type": "FeatureCollection", "features": [
      {"type": "Feature", "geometry": {"type": "Point", "coordinates": [10.5, 20]},
       "properties": {"brush": "rock", "radius": 4, "rotation": 90, "scale": 1.5, "opacity": 0.5,
                      "tint": "#FF800040", "layer": 3, "variant": 2}},
      {"type": "Feature", "geometry": {"type": "Point", "coordinates": [1, 2]},
       "properties": {"brush": 1, "radius": 3}}]})";
  for (const auto& list :
       {parse(csv, InstanceFileFormat::kCsv), parse(json, InstanceFileFormat::kJson),
        parse(geojson, InstanceFileFormat::kGeoJson)}) {
    ASSERT_EQ(list.size(), 2u);
    const BrushInstance& a = list[0];
    EXPECT_EQ(a.brush, 0u);
    EXPECT_EQ(a.x_px, 10.5);
    EXPECT_EQ(a.radius_px, 4.0f);
    EXPECT_FLOAT_EQ(a.rotation_rad, 1.5707964f);
    EXPECT_EQ(a.scale, 1.5f);
    EXPECT_EQ(a.opacity, 128);
    EXPECT_EQ(a.tint_rgba, 0x400080FFu);
    EXPECT_EQ(a.layer, 3);
    EXPECT_EQ(a.variant, 2);
    EXPECT_EQ(list[1].brush, 1u);
    EXPECT_EQ(list[1].scale, 1.0f);
    EXPECT_EQ(list[1].opacity, 255);
  }
}

TEST(InstanceImport, CsvErrorsNameLineAndColumn) {
  const char* header = "brush,x,y,radius\n";
  EXPECT_EQ(
      parseError(std::string(header) + "rock,1,2,3\nrock,1,abc,3\n", InstanceFileFormat::kCsv),
      "in:3:3: y: 'abc' is not a number");
  EXPECT_EQ(parseError(std::string(header) + "moss,1,2,3\n", InstanceFileFormat::kCsv),
            "in:2:1: brush: no brush 'moss'");
  EXPECT_EQ(parseError(std::string(header) + "rock,1,2,-3\n", InstanceFileFormat::kCsv),
            "in:2:4: radius: -3 is not positive");
  EXPECT_EQ(parseError(std::string(header) + "rock,1,2\n", InstanceFileFormat::kCsv),
            "in:2: 3 columns, the header has 4");
  EXPECT_EQ(parseError("brush,x,radius\nrock,1,2\n", InstanceFileFormat::kCsv),
            "in:1: header lacks the column 'y'");
  EXPECT_EQ(parseError("brush,x,y,radius,size\nrock,1,2,3,4\n", InstanceFileFormat::kCsv),
            "in:2:5: unknown field 'size'");
  EXPECT_EQ(
      parseError(std::string(header) + "rock,1,2,3\nrock,\"1,2,3\n", InstanceFileFormat::kCsv),
      "in:3: unterminated quote");
  EXPECT_EQ(parseError("brush,x,y,radius,tint\nrock,1,2,3,#12345\n", InstanceFileFormat::kCsv),
            "in:2:5: tint: '#12345' is not #RRGGBB or #RRGGBBAA");
}

TEST(InstanceImport, JsonErrorsNameLineColumnOrPath) {
  std::string syntax =
      parseError("[\n  {\"brush\": \"rock\",\n   \"x\": 1,, }\n]", InstanceFileFormat::kJson);
  EXPECT_EQ(syntax.rfind("in:3:", 0), 0u) << syntax;
  EXPECT_NE(syntax.find("JSON syntax error"), std::string::npos);
  // Valid syntax, but beyond a double: the parser throws out_of_range, not parse_error.
  EXPECT_EQ(parseError(R"([{"brush": "rock", "x": 1e999, "y": 2, "radius": 1}])",
                       InstanceFileFormat::kJson)
                .rfind("in: JSON error: ", 0),
            0u);
  EXPECT_EQ(parseError(R"([{"brush": "rock", "x": 1, "y": 2, "radius": 1},
                           {"brush": "rock", "x": 1, "y": 2, "radius": "big"}])",
                       InstanceFileFormat::kJson),
            "in: /1: radius: 'big' is not a number");
  EXPECT_EQ(parseError(R"({"instances": [{"brush": "rock", "x": 1, "radius": 1}]})",
                       InstanceFileFormat::kJson),
            "in: /instances/0: 'x' and 'y' missing");
  EXPECT_EQ(parseError(R"({"type": "FeatureCollection", "features": [
                 {"type": "Feature", "geometry": {"type": "LineString", "coordinates": []}}]})",
                       InstanceFileFormat::kGeoJson),
            "in: /features/0: not a Point feature");
}

TEST(InstanceImport, ABadRowImportsNothing) {
  std::string path = (std::filesystem::temp_directory_path() /
                      ("tessera-import-" + std::to_string(::getpid()) + ".sqlite"))
                         .string();
  std::string csv_path = path + ".csv";
  {
    auto db = openSqliteBrushDatabase(path, true);
    ASSERT_TRUE(db) << db.error().message;
    Brush rock;
    rock.name = "rock";
    rock.images.push_back(testing::solidImage(4, 4, 1, 2, 3, 255));
    ASSERT_TRUE((*db)->addBrush(rock));
    std::ofstream(csv_path) << "brush,x,y,radius\n"
                            << "rock,1,1,1\n"
                            << "rock,2,2,2\n"
                            << "rock,3,3,x\n";
    auto bad = importInstances(**db, csv_path);
    ASSERT_FALSE(bad);
    EXPECT_EQ(bad.error().message, csv_path + ":4:4: radius: 'x' is not a number");
    EXPECT_EQ(*(*db)->instanceCount(), 0u);
    std::ofstream(csv_path) << "brush,x,y,radius\n"
                            << "rock,1,1,1\n"
                            << "0,2,2,2\n";
    auto good = importInstances(**db, csv_path);
    ASSERT_TRUE(good) << good.error().message;
    EXPECT_EQ(good->instances, 2u);
    EXPECT_EQ(good->first_id, 1u);
    EXPECT_EQ(good->last_id, 2u);
    EXPECT_FALSE(importInstances(**db, path + ".txt"));
  }
  for (const std::string& p : {path, path + "-wal", path + "-shm", csv_path})
    std::filesystem::remove(p);
}

TEST(InstanceGenerator, IsDeterministicAndRealistic) {
  auto a = generateInstances(20000, {8192, 8192}, 6, 9);
  auto b = generateInstances(20000, {8192, 8192}, 6, 9);
  ASSERT_EQ(a.size(), 20000u);
  size_t large = 0, small = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].x_px, b[i].x_px);
    EXPECT_TRUE(validateInstance(a[i], "generated"));
    if (a[i].radius_px > 1000) ++large;
    if (a[i].radius_px < 50) ++small;
  }
  EXPECT_GE(large, 4u);
  EXPECT_GT(small, 15000u);
}

}  // namespace
}  // namespace tessera
