// The archive's cache of decoded parents: what it was offered is found, the first copy of a
// tile stays, and beyond its byte budget the oldest tiles go first, the newest never.
#include "recent_parents.h"

#include <gtest/gtest.h>

namespace tessera::detail {
namespace {

std::shared_ptr<const Image> tileOf(uint32_t side, uint8_t value) {
  auto image = std::make_shared<Image>(side, side, 1);
  std::fill(image->texels.begin(), image->texels.end(), value);
  return image;
}

TEST(RecentParents, FindsWhatItWasOfferedAndKeepsTheFirstCopy) {
  RecentParents parents;
  const TileId id{0, 1, 2, 3};
  EXPECT_EQ(parents.find(id), nullptr);
  auto first = tileOf(8, 1);
  parents.offer(id, first);
  parents.offer(id, tileOf(8, 2));
  EXPECT_EQ(parents.find(id), first);
  EXPECT_EQ(parents.find({1, 1, 2, 3}), nullptr);  // another image
  EXPECT_EQ(parents.bytes(), 64u);
}

TEST(RecentParents, DropsTheOldestBeyondItsBudgetAndAlwaysKeepsTheNewest) {
  RecentParents parents(200);  // three 64-byte tiles fit
  for (uint32_t x = 0; x < 4; ++x) parents.offer({0, 1, x, 0}, tileOf(8, uint8_t(x)));
  EXPECT_EQ(parents.find({0, 1, 0, 0}), nullptr);
  for (uint32_t x = 1; x < 4; ++x) EXPECT_NE(parents.find({0, 1, x, 0}), nullptr) << x;
  EXPECT_EQ(parents.bytes(), 192u);
  parents.offer({0, 2, 0, 0}, tileOf(16, 9));  // 256 bytes: alone over the budget
  EXPECT_NE(parents.find({0, 2, 0, 0}), nullptr);
  EXPECT_EQ(parents.bytes(), 256u);
}

}  // namespace
}  // namespace tessera::detail
