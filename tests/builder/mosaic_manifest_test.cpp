// Mosaic manifests as documents: paths resolve against the manifest's folder, and bad JSON,
// a wrong schema and absurd numbers are refused naming the manifest, the entry and the
// problem, before any image is opened.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include "builder/mosaic_manifest.h"
#include "support/test_images.h"

namespace tessera {
namespace {

/// The manifest `text` written to a fresh folder, and read.
Result<detail::MosaicManifest> readText(const std::string& text, std::string* path) {
  *path = test::testTempDir() + "m.json";
  EXPECT_TRUE(test::writeFileBytes(*path, {text.begin(), text.end()}));
  return detail::readMosaicManifest(*path);
}

TEST(MosaicManifest, ResolvesPathsAgainstTheManifestFolder) {
  std::string path;
  auto manifest = readText(R"({"width": 300, "height": 200, "background": [1, 2, 3, 4],
    "images": [{"path": "sub/a.tif", "x": 0, "y": 7, "width": 30},
               {"path": "/abs/b.png", "x": 9, "y": 0}]})",
                           &path);
  ASSERT_TRUE(manifest) << manifest.error().message;
  const std::string dir = path.substr(0, path.size() - std::string("m.json").size());
  EXPECT_EQ(manifest->width_px, 300u);
  EXPECT_EQ(manifest->height_px, 200u);
  EXPECT_EQ(manifest->background, (std::vector<double>{1, 2, 3, 4}));
  ASSERT_EQ(manifest->images.size(), 2u);
  EXPECT_EQ(manifest->images[0].path, dir + "sub/a.tif");
  EXPECT_EQ(manifest->images[0].y_px, 7u);
  EXPECT_EQ(manifest->images[0].width_px, 30u);
  EXPECT_EQ(manifest->images[0].height_px, 0u);  // not stated: the file's
  EXPECT_EQ(manifest->images[1].path, "/abs/b.png");
  EXPECT_EQ(manifest->images[1].x_px, 9u);
  EXPECT_EQ(manifest->where(1), path + ": images[1] (/abs/b.png)");
}

TEST(MosaicManifest, RefusesBadJsonSchemaAndAbsurdNumbers) {
  const std::string image = R"({"path": "a.tif", "x": 0, "y": 0})";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"{\"images\": [\n  {\"path\": \"a.tif\",, }]}",
       "m.json:2:20: bad JSON: syntax error while parsing object key"},
      {"[1, 2]", "m.json: a mosaic manifest is a JSON object"},
      {R"({"images": []})", "m.json: \"images\" missing or not a non-empty array"},
      {R"({"imgaes": [{}]})", "m.json: unknown key \"imgaes\" (known: \"width\", \"height\""},
      {R"({"width": 100000000, "images": [)" + image + "]}",
       "m.json: \"width\" is 100000000, over the limit of 16777216 px"},
      {R"({"height": 0, "images": [)" + image + "]}", "canvas width or height must be >= 1"},
      {R"({"background": "white", "images": [)" + image + "]}",
       "m.json: \"background\" is \"white\", want 1 to 4 numbers"},
      {R"({"images": [)" + image + R"(, {"path": "b.tif", "x": -3, "y": 0}]})",
       "m.json: images[1] (b.tif): \"x\" is -3, want a whole number of pixels >= 0"},
      {R"({"images": [{"path": "b.tif", "x": 1.5, "y": 0}]})", "\"x\" is 1.5, want a whole"},
      {R"({"images": [{"path": "b.tif", "x": 1}]})", "images[0] (b.tif): \"y\" missing"},
      {R"({"images": [{"x": 1, "y": 2}]})", "images[0]: \"path\" missing"},
      {R"({"images": [{"path": "b.tif", "x": 0, "y": 0, "widht": 4}]})",
       "images[0]: unknown key \"widht\""},
      {R"({"images": [7]})", "images[0]: want an object"},
      // Valid syntax, but beyond a double: the parser throws out_of_range, not parse_error.
      {R"({"width": 1e999, "images": [)" + image + "]}", "m.json: bad JSON: "}};
  for (const auto& [text, expected] : cases) {
    std::string path;
    auto manifest = readText(text, &path);
    ASSERT_FALSE(manifest) << text;
    EXPECT_NE(manifest.error().message.find(expected), std::string::npos)
        << manifest.error().message;
  }
}

TEST(MosaicManifest, SniffsJsonObjectsOnly) {
  auto sniff = [](const std::string& bytes) {
    return detail::looksLikeManifest(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
  };
  EXPECT_TRUE(sniff("{\"images\": []}"));
  EXPECT_TRUE(sniff("\xef\xbb\xbf \r\n\t{"));
  EXPECT_FALSE(sniff("[{}]"));
  EXPECT_FALSE(sniff("   "));
  EXPECT_FALSE(sniff("\x89PNG\r\n\x1a\n"));
}

}  // namespace
}  // namespace tessera
