// The row loop the PNG and JPEG readers share, over a fake decoder: rows in order, the end of
// the data checked once after the last row, and a decoder error reported naming the row and
// then repeated without calling the decoder again.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <vector>

#include "builder/scanline_reader.h"

namespace tessera::detail {
namespace {

using ::testing::HasSubstr;

/// Rows whose every byte is the row's index; fails at `fail_row` (or at the end) on request.
class FakeReader final : public ScanlineReader {
 public:
  FakeReader(uint32_t width_px, uint32_t height_px, uint32_t channels)
      : ScanlineReader("fake.img") {
    info_.width_px = width_px;
    info_.height_px = height_px;
    info_.channels = channels;
  }
  uint32_t fail_row = UINT32_MAX;
  bool fail_finish = false;
  uint32_t rows_decoded = 0;
  uint32_t finishes = 0;

 private:
  bool decodeRow(uint8_t* row) override {
    if (rows_decoded == fail_row) return false;
    std::fill(row, row + size_t(info_.width_px) * info_.channels, uint8_t(rows_decoded));
    ++rows_decoded;
    return true;
  }
  bool finishDecoding() override {
    ++finishes;
    return !fail_finish;
  }
  const char* decoderMessage() const override { return "bad huffman code"; }
};

TEST(ScanlineReader, ReadsRowsInOrderAndChecksTheEndOnceAfterTheLastRow) {
  FakeReader reader(3, 5, 2);
  std::vector<uint8_t> band(3 * 3 * 2);
  ASSERT_TRUE(reader.readRows(3, band));
  EXPECT_EQ(band, std::vector<uint8_t>({0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 2, 2, 2, 2, 2, 2}));
  EXPECT_EQ(reader.finishes, 0u);
  ASSERT_TRUE(reader.readRows(2, band));
  EXPECT_EQ(std::vector<uint8_t>(band.begin(), band.begin() + 12),
            std::vector<uint8_t>({3, 3, 3, 3, 3, 3, 4, 4, 4, 4, 4, 4}));
  EXPECT_EQ(reader.finishes, 1u);
}

TEST(ScanlineReader, ADecoderErrorNamesTheFileAndRowAndIsRepeatedWithoutDecoding) {
  FakeReader reader(4, 6, 1);
  reader.fail_row = 2;
  std::vector<uint8_t> band(4 * 6);
  auto first = reader.readRows(4, band);
  ASSERT_FALSE(first);
  EXPECT_EQ(first.error().code, ErrorCode::kCorrupt);
  EXPECT_EQ(first.error().message, "fake.img: row 2: truncated or corrupt data (bad huffman code)");
  reader.fail_row = UINT32_MAX;  // a decoder's state is undefined after an error: never asked
  auto again = reader.readRows(1, band);
  ASSERT_FALSE(again);
  EXPECT_EQ(again.error().message, first.error().message);
  EXPECT_EQ(reader.rows_decoded, 2u);
}

TEST(ScanlineReader, DataCutOrPaddedAfterTheLastRowFails) {
  FakeReader reader(2, 2, 3);
  reader.fail_finish = true;
  std::vector<uint8_t> band(2 * 2 * 3);
  auto read = reader.readRows(2, band);
  ASSERT_FALSE(read);
  EXPECT_THAT(read.error().message,
              HasSubstr("fake.img: after the last row: truncated or corrupt"));
}

}  // namespace
}  // namespace tessera::detail
