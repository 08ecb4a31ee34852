// The coverage hints section (docs/format.md, "Coverage hints"): golden bytes written by hand
// from the spec's tables, the round trip, every prefix rejected, and each rule's violation
// rejected naming the field.
#include "format/coverage_hints.h"

#include <cstring>

#include <gtest/gtest.h>

#include "format/byte_io.h"

namespace tessera::detail {
namespace {

CoverageHints smallHints() {
  CoverageHints h;
  h.up_axis = 1;
  h.cells_u = 2;
  h.cells_v = 1;
  h.origin_u = -8.0f;
  h.origin_v = 0.5f;
  h.cell_size = 4.0f;
  h.eye_low = 1.0f;
  h.eye_high = 2.5f;
  h.resolution_px = 64;
  h.texture_count = 3;
  h.cell_first = {0, 2, 3};
  h.entries = {{0, 0x8000}, {2, 1}, {1, 0xFFFF}};
  return h;
}

TEST(CoverageHints, GoldenBytes) {
  const uint8_t golden[88] = {
      'T', 'C', 'V',  'H',  1, 0, 1, 0,  // magic, version 1, up axis y, reserved
      2,   0,   0,    0,    1, 0, 0, 0,  // cells_u 2, cells_v 1
      3,   0,   0,    0,    3, 0, 0, 0,  // texture_count 3, entry_count 3
      0,   0,   0,    0xC1,              // origin_u -8.0f
      0,   0,   0,    0x3F,              // origin_v 0.5f
      0,   0,   0x80, 0x40,              // cell_size 4.0f
      0,   0,   0x80, 0x3F,              // eye_low 1.0f
      0,   0,   0x20, 0x40,              // eye_high 2.5f
      64,  0,   8,    6,                 // resolution 64, 8 positions, 6 directions
      0,   0,   0,    0,    0, 0, 0, 0,  // reserved
      0,   0,   0,    0,    0, 0, 0, 0,  //
      0,   0,   0,    0,                 // cell 0 starts at entry 0
      2,   0,   0,    0,                 // cell 1 at entry 2
      3,   0,   0,    0,                 // end
      0,   0,   0,    0x80,              // texture 0, coverage 0x8000
      2,   0,   1,    0,                 // texture 2, coverage 1
      1,   0,   0xFF, 0xFF,              // cell 1: texture 1, coverage 0xFFFF
  };
  const std::vector<uint8_t> bytes = encodeCoverageHints(smallHints());
  ASSERT_EQ(bytes.size(), sizeof(golden));
  EXPECT_EQ(0, std::memcmp(bytes.data(), golden, sizeof(golden)));
  auto decoded = decodeCoverageHints(bytes, 3, "t.tess");
  ASSERT_TRUE(decoded) << decoded.error().message;
  EXPECT_EQ(*decoded, smallHints());
  ASSERT_EQ(decoded->cell(0).size(), 2u);
  EXPECT_EQ(decoded->cell(1)[0].texture, 1u);
  EXPECT_DOUBLE_EQ(decoded->cell(1)[0].coverage(), 1.0);
}

TEST(CoverageHints, CellAtClampsWithinOneCellAndRefusesFurther) {
  const CoverageHints h = smallHints();  // u = x in [-8, 0), v = z in [0.5, 4.5)
  const double inside[3] = {-3, 100, 1}, left[3] = {-11, 0, 1}, far[3] = {-13, 0, 1};
  EXPECT_EQ(h.cellAt(inside), 1);
  EXPECT_EQ(h.cellAt(left), 0);
  EXPECT_EQ(h.cellAt(far), -1);
}

TEST(CoverageHints, DecodeRejectsEveryPrefixAndTrailingBytes) {
  const std::vector<uint8_t> bytes = encodeCoverageHints(smallHints());
  for (size_t n = 0; n < bytes.size(); ++n) {
    std::vector<uint8_t> prefix(bytes.begin(), bytes.begin() + n);
    EXPECT_FALSE(decodeCoverageHints(prefix, 3, "t.tess")) << n;
  }
  std::vector<uint8_t> longer = bytes;
  longer.push_back(0);
  EXPECT_FALSE(decodeCoverageHints(longer, 3, "t.tess"));
}

TEST(CoverageHints, DecodeRejectsBrokenRules) {
  const std::vector<uint8_t> good = encodeCoverageHints(smallHints());
  struct Case {
    const char* what;
    size_t offset;
    std::vector<uint8_t> value;
    const char* message;
  };
  const Case cases[] = {
      {"magic", 0, {'X'}, "TCVH"},
      {"up axis", 6, {3}, "up axis"},
      {"reserved", 50, {1}, "reserved"},
      {"zero cells", 8, {0}, "cells"},
      {"cell size", 32, {0, 0, 0x80, 0xBF}, "cell size"},  // -1.0f
      {"eye heights", 40, {0, 0, 0, 0}, "eye heights"},    // high 0 < low 1
      {"resolution", 44, {0, 0}, "resolution"},
      {"texture count", 16, {4}, "textures"},
      {"cell order", 68, {4}, "cell table"},
      {"texture order", 84, {0}, "order"},  // cell 1's only entry is fine; break cell 0's
      {"texture range", 80, {3}, "range"},
      {"zero coverage", 78, {0, 0}, "range"},
  };
  for (const Case& c : cases) {
    std::vector<uint8_t> bytes = good;
    std::memcpy(bytes.data() + c.offset, c.value.data(), c.value.size());
    if (std::string(c.what) == "texture order") {
      storeU16(bytes.data() + 76, 2);  // cell 0: texture 2 then 2
    }
    auto decoded = decodeCoverageHints(bytes, 3, "t.tess");
    ASSERT_FALSE(decoded) << c.what;
    EXPECT_NE(decoded.error().message.find("t.tess: coverage hints"), std::string::npos);
    EXPECT_NE(decoded.error().message.find(c.message), std::string::npos)
        << c.what << ": " << decoded.error().message;
  }
  std::vector<uint8_t> newer = good;
  newer[4] = 2;
  auto decoded = decodeCoverageHints(newer, 3, "t.tess");
  ASSERT_FALSE(decoded);
  EXPECT_EQ(decoded.error().code, ErrorCode::kUnsupported);
}

}  // namespace
}  // namespace tessera::detail
