// FileAppender with AppendWrites::kBackground: a second thread writes each full buffer, and
// bytes appended where they lie, while the caller goes on filling; the file must hold exactly
// what inline writes leave, and every owned block must be released once, by flush().
#include "output/file_appender.h"

#include <algorithm>
#include <atomic>
#include <cstring>
#include <deque>
#include <random>

#include <gtest/gtest.h>

#include "support/test_images.h"

namespace tessera::detail {
namespace {

struct Written {
  std::vector<uint8_t> bytes;  ///< the whole file as read back
  std::vector<uint8_t> expected;
  int owned_blocks = 0;
  int released = 0;
};

/// The same random mix of appends (small, filled, over the buffer, owned, holes) through an
/// appender writing as `writes` says.
Written appendMix(const std::string& path, AppendWrites writes) {
  Written result;
  auto file = TempFile::create(path);
  EXPECT_TRUE(file) << file.error().message;
  if (!file) return result;
  constexpr uint64_t kStart = 100;
  std::vector<uint8_t>& expected = result.expected;
  expected.assign(kStart, 0);
  std::atomic<int> released{0};
  std::deque<std::vector<uint8_t>> owned;  // outlives the appender's writes
  std::mt19937 random(21);
  auto random_bytes = [&](size_t size) {  // a pattern of its own per block
    std::vector<uint8_t> pattern(251), bytes(size);
    const uint32_t seed = random();
    for (size_t i = 0; i < pattern.size(); ++i) pattern[i] = uint8_t(seed + i * 131);
    for (size_t at = 0; at < size; at += pattern.size())
      std::memcpy(bytes.data() + at, pattern.data(), std::min(pattern.size(), size - at));
    return bytes;
  };
  {
    FileAppender appender(*file, kStart, writes);
    for (int step = 0; step < 48; ++step) {
      const int kind = step == 7 ? 2 : int(random() % 5);
      // Step 7 is one block over the buffer; the rest stay under 96 KiB.
      const size_t size = kind == 2 ? FileAppender::kBufferBytes + 4099 : random() % (96 << 10);
      Result<uint64_t> offset = uint64_t(0);
      if (kind == 4) {
        offset = appender.skip(size % 5000);
        expected.resize(expected.size() + size % 5000, 0);
      } else if (kind == 3) {
        owned.push_back(random_bytes(size));
        offset = appender.appendOwned({owned.back(), [&released] { ++released; }});
        ++result.owned_blocks;
        expected.insert(expected.end(), owned.back().begin(), owned.back().end());
      } else {
        const std::vector<uint8_t> bytes = random_bytes(size);
        offset = kind == 0 ? appender.append(bytes)
                           : appender.appendFilled(size, [&](std::span<uint8_t> place) {
                               std::memcpy(place.data(), bytes.data(), size);
                               return Result<void>();
                             });
        expected.insert(expected.end(), bytes.begin(), bytes.end());
      }
      EXPECT_TRUE(offset) << offset.error().message;
      if (offset && kind != 4) {
        EXPECT_EQ(*offset + size, expected.size()) << "step " << step;
      }
    }
    EXPECT_TRUE(appender.flush());
    result.released = released.load();
  }
  result.bytes.resize(expected.size());
  EXPECT_TRUE(file->pread(0, result.bytes));
  return result;
}

TEST(FileAppender, BackgroundWritesLeaveTheBytesOfInlineWrites) {
  const std::string dir = test::testTempDir();
  const Written inline_written = appendMix(dir + "inline.bin", AppendWrites::kInline);
  const Written background = appendMix(dir + "background.bin", AppendWrites::kBackground);
  EXPECT_GT(background.expected.size(), 2 * FileAppender::kBufferBytes);
  EXPECT_TRUE(inline_written.bytes == inline_written.expected);
  EXPECT_TRUE(background.bytes == background.expected);
  EXPECT_TRUE(background.expected == inline_written.expected);
  EXPECT_GT(background.owned_blocks, 3);
  EXPECT_EQ(background.released, background.owned_blocks);
  EXPECT_EQ(inline_written.released, inline_written.owned_blocks);
}

}  // namespace
}  // namespace tessera::detail
