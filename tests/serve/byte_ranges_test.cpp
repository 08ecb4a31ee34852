// The Range header grammar (RFC 9110, section 14.1.2) resolved against a size.
#include "serve/byte_ranges.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

namespace tessera::detail {
namespace {

using Ranges = std::vector<ResolvedRange>;

TEST(ByteRanges, ResolvesTheThreeFormsOfRangeSpec) {
  RangeRequest r = parseRangeHeader("bytes=0-99, 200-, -50", 1000, 16);
  ASSERT_EQ(r.verdict, RangeVerdict::kSatisfiable);
  // 200- and -50 overlap (950..999 lies inside 200..999), so they are coalesced.
  EXPECT_EQ(r.ranges, (Ranges{{0, 100}, {200, 800}}));
}

TEST(ByteRanges, KeepsRequestOrderWhenNothingOverlaps) {
  RangeRequest r = parseRangeHeader("bytes=500-599,0-9", 1000, 16);
  ASSERT_EQ(r.verdict, RangeVerdict::kSatisfiable);
  EXPECT_EQ(r.ranges, (Ranges{{500, 100}, {0, 10}}));
}

TEST(ByteRanges, ClampsTheLastBytePosAndTheSuffixToTheSize) {
  RangeRequest r = parseRangeHeader("bytes=990-5000", 1000, 16);
  ASSERT_EQ(r.verdict, RangeVerdict::kSatisfiable);
  EXPECT_EQ(r.ranges, (Ranges{{990, 10}}));
  r = parseRangeHeader("bytes=-5000", 1000, 16);
  EXPECT_EQ(r.ranges, (Ranges{{0, 1000}}));
}

TEST(ByteRanges, RangesWhollyPastTheEndAreUnsatisfiable) {
  EXPECT_EQ(parseRangeHeader("bytes=1000-", 1000, 16).verdict, RangeVerdict::kUnsatisfiable);
  EXPECT_EQ(parseRangeHeader("bytes=5000-6000,1000-1001", 1000, 16).verdict,
            RangeVerdict::kUnsatisfiable);
  EXPECT_EQ(parseRangeHeader("bytes=-0", 1000, 16).verdict, RangeVerdict::kUnsatisfiable);
  // One satisfiable range among unsatisfiable ones is served alone.
  RangeRequest r = parseRangeHeader("bytes=5000-,10-19", 1000, 16);
  ASSERT_EQ(r.verdict, RangeVerdict::kSatisfiable);
  EXPECT_EQ(r.ranges, (Ranges{{10, 10}}));
}

TEST(ByteRanges, OverlappingAndAdjacentRangesAreCoalesced) {
  RangeRequest r = parseRangeHeader("bytes=0-9,5-14,15-19,100-109,0-1", 1000, 16);
  ASSERT_EQ(r.verdict, RangeVerdict::kSatisfiable);
  EXPECT_EQ(r.ranges, (Ranges{{0, 20}, {100, 10}}));
}

TEST(ByteRanges, MoreThanTheLimitIsRefused) {
  std::string header = "bytes=0-0";
  for (int i = 1; i < 17; ++i) header += fmt::format(",{0}-{0}", i * 2);
  EXPECT_EQ(parseRangeHeader(header, 1000, 16).verdict, RangeVerdict::kTooManyRanges);
  EXPECT_EQ(parseRangeHeader(header, 1000, 17).verdict, RangeVerdict::kSatisfiable);
}

TEST(ByteRanges, InvalidSyntaxIsIgnored) {
  for (const char* header :
       {"bytes=", "bytes=a-b", "bytes=5-3", "bytes=--5", "bytes=+1-2", "bytes=1-2-3", "items=0-1",
        "bytes 0-1", "bytes=0x10-20", "bytes=99999999999999999999-", "bytes=1 -2", ""})
    EXPECT_EQ(parseRangeHeader(header, 1000, 16).verdict, RangeVerdict::kIgnore) << header;
}

TEST(ByteRanges, UnitIsCaseInsensitiveAndListElementsMayBeEmpty) {
  RangeRequest r = parseRangeHeader("Bytes= 1-2 ,, 4-5", 1000, 16);
  ASSERT_EQ(r.verdict, RangeVerdict::kSatisfiable);
  EXPECT_EQ(r.ranges, (Ranges{{1, 2}, {4, 2}}));
}

TEST(ByteRanges, EmptyRepresentationHasNoSatisfiableRange) {
  EXPECT_EQ(parseRangeHeader("bytes=0-", 0, 16).verdict, RangeVerdict::kUnsatisfiable);
  EXPECT_EQ(parseRangeHeader("bytes=-1", 0, 16).verdict, RangeVerdict::kUnsatisfiable);
}

}  // namespace
}  // namespace tessera::detail
