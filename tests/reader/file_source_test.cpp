// The pread-based file source: exact reads, errors that name the file, readMany.
#include <tessera/byte_source.h>

#include <algorithm>
#include <atomic>
#include <thread>

#include <gtest/gtest.h>

#include "support/test_images.h"

namespace tessera {
namespace {

std::vector<uint8_t> countingBytes(size_t n) {
  std::vector<uint8_t> bytes(n);
  for (size_t i = 0; i < n; ++i) bytes[i] = uint8_t(i * 7 + (i >> 8));
  return bytes;
}

std::shared_ptr<ByteSource> openWritten(const std::vector<uint8_t>& bytes, std::string* path) {
  *path = test::testTempDir() + "data.bin";
  EXPECT_TRUE(test::writeFileBytes(*path, bytes));
  auto source = openFileSource(*path);
  EXPECT_TRUE(source) << source.error().message;
  return source ? *source : nullptr;
}

TEST(FileSource, ReportsSizeAndNameAndReadsExactRanges) {
  const std::vector<uint8_t> bytes = countingBytes(100000);
  std::string path;
  auto source = openWritten(bytes, &path);
  ASSERT_TRUE(source);
  EXPECT_EQ(source->sizeBytes(), bytes.size());
  EXPECT_EQ(source->name(), path);
  for (auto [offset, length] : {std::pair<size_t, size_t>{0, 1},
                                {0, 100000},
                                {99999, 1},
                                {12345, 54321},
                                {65535, 2},
                                {100000, 0}}) {
    std::vector<uint8_t> out(length, 0xCD);
    ASSERT_TRUE(source->read(offset, out)) << offset << "+" << length;
    EXPECT_TRUE(std::equal(out.begin(), out.end(), bytes.begin() + offset)) << offset;
  }
}

TEST(FileSource, ReadPastTheEndFailsNamingTheFileAndRange) {
  std::string path;
  auto source = openWritten(countingBytes(1000), &path);
  ASSERT_TRUE(source);
  std::vector<uint8_t> out(10);
  for (uint64_t offset : {991ull, 1000ull, 1001ull, ~0ull, ~0ull - 5}) {
    auto read = source->read(offset, out);
    ASSERT_FALSE(read) << offset;
    EXPECT_EQ(read.error().code, ErrorCode::kIo);
    EXPECT_NE(read.error().message.find(path), std::string::npos);
    EXPECT_NE(read.error().message.find("past the end"), std::string::npos) << read.error().message;
  }
}

TEST(FileSource, AMissingFileIsNotFound) {
  std::string path = test::testTempDir() + "absent.tess";
  auto source = openFileSource(path);
  ASSERT_FALSE(source);
  EXPECT_EQ(source.error().code, ErrorCode::kNotFound);
  EXPECT_NE(source.error().message.find(path), std::string::npos);
}

TEST(FileSource, ADirectoryIsNotARegularFile) {
  std::string dir = test::testTempDir();
  auto source = openFileSource(dir);
  ASSERT_FALSE(source);
  EXPECT_NE(source.error().code, ErrorCode::kNotFound);
  EXPECT_NE(source.error().message.find(dir), std::string::npos);
}

TEST(FileSource, AnEmptyFileHasSizeZeroAndRefusesReads) {
  std::string path;
  auto source = openWritten({}, &path);
  ASSERT_TRUE(source);
  EXPECT_EQ(source->sizeBytes(), 0u);
  uint8_t byte = 0;
  EXPECT_FALSE(source->read(0, {&byte, 1}));
  EXPECT_TRUE(source->read(0, {}));
}

TEST(FileSource, AFileShrunkAfterOpenFailsInsteadOfCrashing) {
  std::string path;
  auto source = openWritten(countingBytes(5000), &path);
  ASSERT_TRUE(source);
  ASSERT_TRUE(test::writeFileBytes(path, countingBytes(100)));
  std::vector<uint8_t> out(100);
  auto read = source->read(4000, out);
  ASSERT_FALSE(read);
  EXPECT_EQ(read.error().code, ErrorCode::kIo);
  EXPECT_NE(read.error().message.find(path), std::string::npos);
}

TEST(FileSource, ReadManyFillsEveryRange) {
  const std::vector<uint8_t> bytes = countingBytes(70000);
  std::string path;
  auto source = openWritten(bytes, &path);
  ASSERT_TRUE(source);
  std::vector<std::vector<uint8_t>> outs = {std::vector<uint8_t>(10), std::vector<uint8_t>(4096),
                                            std::vector<uint8_t>(1), std::vector<uint8_t>(0)};
  const uint64_t offsets[] = {69990, 0, 33333, 5};
  std::vector<ByteRange> ranges;
  for (size_t i = 0; i < outs.size(); ++i)
    ranges.push_back({offsets[i], outs[i].size(), outs[i].data()});
  ASSERT_TRUE(source->readMany(ranges));
  for (size_t i = 0; i < outs.size(); ++i)
    EXPECT_TRUE(std::equal(outs[i].begin(), outs[i].end(), bytes.begin() + offsets[i])) << i;
}

TEST(FileSource, ReadManyFailsAsAWholeWhenOneRangeFails) {
  std::string path;
  auto source = openWritten(countingBytes(100), &path);
  ASSERT_TRUE(source);
  uint8_t a[4], b[4];
  const ByteRange ranges[] = {{0, 4, a}, {98, 4, b}};
  auto read = source->readMany(ranges);
  ASSERT_FALSE(read);
  EXPECT_NE(read.error().message.find(path), std::string::npos);
}

TEST(FileSource, PrefetchAsksForTheRangesInsideTheFileAndLeavesReadsIntact) {
  const std::vector<uint8_t> bytes = countingBytes(70000);
  std::string path;
  auto source = openWritten(bytes, &path);
  ASSERT_TRUE(source);
  // One range inside, one running past the end (clipped), one wholly past it and an empty one
  // (both ignored): a hint never fails.
  const ByteRange ranges[] = {
      {100, 5000, nullptr}, {69000, 4000, nullptr}, {80000, 10, nullptr}, {10, 0, nullptr}};
  EXPECT_EQ(source->prefetch(ranges), 5000u + 1000u);
  std::vector<uint8_t> out(6000);
  ASSERT_TRUE(source->read(64000, out));
  EXPECT_TRUE(std::equal(out.begin(), out.end(), bytes.begin() + 64000));
}

TEST(MemorySource, PrefetchIsANoOp) {
  auto source = makeMemorySource(countingBytes(100), "mem:hint");
  const ByteRange range{0, 100, nullptr};
  EXPECT_EQ(source->prefetch({&range, 1}), 0u);
}

TEST(ByteSource, ReadCancellableReadsUntilCancelledThenFailsAsCancelled) {
  const std::vector<uint8_t> bytes = countingBytes(1000);
  auto source = makeMemorySource(bytes, "mem:cancel");
  std::atomic<bool> cancel{false};
  std::vector<uint8_t> out(10);
  ASSERT_TRUE(source->readCancellable(500, out, cancel));
  EXPECT_TRUE(std::equal(out.begin(), out.end(), bytes.begin() + 500));
  cancel = true;
  std::fill(out.begin(), out.end(), uint8_t(0));
  auto cancelled = source->readCancellable(500, out, cancel);
  ASSERT_FALSE(cancelled);
  EXPECT_EQ(cancelled.error().code, ErrorCode::kCancelled);
  EXPECT_NE(cancelled.error().message.find("mem:cancel"), std::string::npos);
  EXPECT_TRUE(std::all_of(out.begin(), out.end(), [](uint8_t b) { return b == 0; }));
}

TEST(FileSource, ConcurrentReadsSeeTheirOwnRanges) {
  const std::vector<uint8_t> bytes = countingBytes(1 << 20);
  std::string path;
  auto source = openWritten(bytes, &path);
  ASSERT_TRUE(source);
  std::atomic<int> mismatches{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      std::vector<uint8_t> out(4093);
      for (uint64_t offset = t * 17; offset + out.size() <= bytes.size(); offset += 65537) {
        if (!source->read(offset, out) ||
            !std::equal(out.begin(), out.end(), bytes.begin() + offset))
          ++mismatches;
      }
    });
  }
  for (auto& thread : threads) thread.join();
  EXPECT_EQ(mismatches.load(), 0);
}

}  // namespace
}  // namespace tessera
