// The in-memory byte source: the same contract as the file source.
#include <tessera/byte_source.h>

#include <gtest/gtest.h>

namespace tessera {
namespace {

std::shared_ptr<ByteSource> makeSource(size_t n) {
  std::vector<uint8_t> bytes(n);
  for (size_t i = 0; i < n; ++i) bytes[i] = uint8_t(i * 13 + 1);
  return makeMemorySource(std::move(bytes), "mem:test");
}

TEST(MemorySource, ReportsSizeAndNameAndReadsExactRanges) {
  auto source = makeSource(300);
  EXPECT_EQ(source->sizeBytes(), 300u);
  EXPECT_EQ(source->name(), "mem:test");
  std::vector<uint8_t> out(50);
  ASSERT_TRUE(source->read(250, out));
  for (size_t i = 0; i < out.size(); ++i) ASSERT_EQ(out[i], uint8_t((250 + i) * 13 + 1));
}

TEST(MemorySource, ReadPastTheEndFailsNamingTheSource) {
  auto source = makeSource(300);
  std::vector<uint8_t> out(2);
  for (uint64_t offset : {299ull, 300ull, 301ull, ~0ull, ~0ull - 1}) {
    auto read = source->read(offset, out);
    ASSERT_FALSE(read) << offset;
    EXPECT_EQ(read.error().code, ErrorCode::kIo);
    EXPECT_NE(read.error().message.find("mem:test"), std::string::npos);
  }
}

TEST(MemorySource, EmptySourceAllowsOnlyEmptyReads) {
  auto source = makeMemorySource({}, "empty");
  EXPECT_EQ(source->sizeBytes(), 0u);
  EXPECT_TRUE(source->read(0, {}));
  uint8_t byte;
  EXPECT_FALSE(source->read(0, {&byte, 1}));
}

TEST(MemorySource, ReadManyFillsEveryRangeOrFailsAsAWhole) {
  auto source = makeSource(1000);
  uint8_t a[3], b[5];
  const ByteRange good[] = {{997, 3, a}, {0, 5, b}};
  ASSERT_TRUE(source->readMany(good));
  EXPECT_EQ(a[2], uint8_t(999 * 13 + 1));
  EXPECT_EQ(b[4], uint8_t(4 * 13 + 1));
  const ByteRange bad[] = {{0, 5, b}, {998, 3, a}};
  EXPECT_FALSE(source->readMany(bad));
}

}  // namespace
}  // namespace tessera
