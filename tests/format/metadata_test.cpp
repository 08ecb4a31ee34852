// The metadata block (docs/format.md, "Metadata"): kept byte for byte, one name per image,
// and rejected when it is not exactly one JSON object; the update record read or refused
// naming the field.
#include "format/metadata.h"

#include <string_view>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

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

TEST(UpdateRecord, DefaultsWhenAbsentAndReadsWhatUpdateWrote) {
  const Result<UpdateRecord> none = parseUpdateRecord(nlohmann::json::object(), "a.tess");
  ASSERT_TRUE(none) << none.error().message;
  EXPECT_FALSE(none->recorded);
  EXPECT_EQ(none->version, 1u);
  EXPECT_EQ(none->dead_bytes, 0u);
  const Result<UpdateRecord> two = parseUpdateRecord(
      nlohmann::json::parse(R"({"update":{"version":2,"dead_bytes":4096}})"), "a.tess");
  ASSERT_TRUE(two) << two.error().message;
  EXPECT_TRUE(two->recorded);
  EXPECT_EQ(two->version, 2u);
  EXPECT_EQ(two->dead_bytes, 4096u);
}

// Each of these threw from nlohmann's accessors before (issue: hostile metadata).
TEST(UpdateRecord, RefusesWrongTypesNamingTheFileAndTheField) {
  const struct {
    const char* json;
    const char* message;
  } cases[] = {
      {R"({"update":{"version":"2"}})",
       R"(a.tess: metadata "update.version" is not an unsigned integer (it is "2"))"},
      {R"({"update":{"version":-1}})",
       R"(a.tess: metadata "update.version" is not an unsigned integer (it is -1))"},
      {R"({"update":{"version":1.5}})",
       R"(a.tess: metadata "update.version" is not an unsigned integer (it is 1.5))"},
      {R"({"update":{"version":2,"dead_bytes":[1]}})",
       R"(a.tess: metadata "update.dead_bytes" is not an unsigned integer (it is [1]))"},
      {R"({"update":7})", R"(a.tess: metadata "update" is not an object)"},
  };
  for (const auto& c : cases) {
    const Result<UpdateRecord> record = parseUpdateRecord(nlohmann::json::parse(c.json), "a.tess");
    ASSERT_FALSE(record) << c.json;
    EXPECT_EQ(record.error().code, ErrorCode::kCorrupt);
    EXPECT_EQ(record.error().message, c.message);
  }
}

TEST(MetadataUnsigned, RefusesAValueAboveItsBound) {
  const Result<uint64_t> fits =
      metadataUnsigned(nlohmann::json(7), "p.tess", "split_part.count", 7);
  ASSERT_TRUE(fits);
  EXPECT_EQ(*fits, 7u);
  const Result<uint64_t> above =
      metadataUnsigned(nlohmann::json(8), "p.tess", "split_part.count", 7);
  ASSERT_FALSE(above);
  EXPECT_EQ(above.error().message, R"(p.tess: metadata "split_part.count" is 8, above 7)");
}

}  // namespace
}  // namespace tessera::detail
