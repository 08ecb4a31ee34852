// The metadata block (docs/format.md, "Metadata"): kept byte for byte, one name per image,
// and rejected when it is not exactly one JSON object.
#include "format/metadata.h"

#include <string_view>

#include <gtest/gtest.h>

namespace tessera::detail {
namespace {

std::span<const uint8_t> asBytes(std::string_view text) {
  return {reinterpret_cast<const uint8_t*>(text.data()), text.size()};
}

TEST(Metadata, KeepsTheBlockAsStoredAndNamesEachImage) {
  const std::string_view text = R"({"images":[{"name":"caf\u00e9"},{"name":7},{"name":"é"}]})";
  const Result<ArchiveMetadata> metadata = parseMetadata(asBytes(text), 4, "a.tess");
  ASSERT_TRUE(metadata) << metadata.error().message;
  EXPECT_EQ(metadata->json, text);
  ASSERT_EQ(metadata->image_names.size(), 4u);
  EXPECT_EQ(metadata->image_names[0], "caf\xc3\xa9");
  EXPECT_EQ(metadata->image_names[1], "");  // not a string
  EXPECT_EQ(metadata->image_names[2], "\xc3\xa9");
  EXPECT_EQ(metadata->image_names[3], "");  // no entry
}

TEST(Metadata, RejectsWhatIsNotOneObject) {
  for (const std::string_view text : {"[1,2]", "{\"a\":1", "", "{} {}", "\"x\""}) {
    const Result<ArchiveMetadata> metadata = parseMetadata(asBytes(text), 1, "a.tess");
    ASSERT_FALSE(metadata) << text;
    EXPECT_EQ(metadata.error().code, ErrorCode::kCorrupt);
    EXPECT_NE(metadata.error().message.find("a.tess"), std::string::npos);
  }
}

// The JSON lexer stops at a NUL byte; what follows must not pass unread.
TEST(Metadata, RejectsANulByteAndWhatFollowsIt) {
  const std::string text("{\"a\":1}\0garbage", 15);
  const Result<ArchiveMetadata> metadata = parseMetadata(asBytes(text), 1, "b.tess");
  ASSERT_FALSE(metadata);
  EXPECT_EQ(metadata.error().code, ErrorCode::kCorrupt);
  EXPECT_NE(metadata.error().message.find("NUL"), std::string::npos);
}

}  // namespace
}  // namespace tessera::detail
