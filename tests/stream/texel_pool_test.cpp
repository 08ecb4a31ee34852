// The pool of recycled tile buffers: exact sizes, the byte cap, and tiles that hand their
// buffer back when their last reference goes.
#include "stream/texel_pool.h"

#include <gtest/gtest.h>

namespace tessera::detail {
namespace {

TEST(TexelPool, TakeIsEmptyUntilABufferOfThatSizeWasGiven) {
  auto pool = std::make_shared<TexelPool>(1 << 20);
  EXPECT_TRUE(pool->take(1000).empty());
  std::vector<uint8_t> buffer(1000, 7);
  const uint8_t* address = buffer.data();
  pool->give(std::move(buffer));
  EXPECT_EQ(pool->idleBytes(), 1000u);
  EXPECT_TRUE(pool->take(999).empty());  // another tile size: not this buffer
  std::vector<uint8_t> taken = pool->take(1000);
  ASSERT_EQ(taken.size(), 1000u);
  EXPECT_EQ(taken.data(), address);  // the same allocation, not a copy
  EXPECT_EQ(pool->idleBytes(), 0u);
  EXPECT_TRUE(pool->take(1000).empty());
}

TEST(TexelPool, KeepsNoMoreThanItsCap) {
  auto pool = std::make_shared<TexelPool>(2500);
  for (int i = 0; i < 5; ++i) pool->give(std::vector<uint8_t>(1000));
  EXPECT_EQ(pool->idleBytes(), 2000u);
  EXPECT_FALSE(pool->take(1000).empty());
  EXPECT_FALSE(pool->take(1000).empty());
  EXPECT_TRUE(pool->take(1000).empty());
  pool->give({});  // an empty buffer is not kept
  EXPECT_EQ(pool->idleBytes(), 0u);
}

TEST(TexelPool, ATileGivesItsBufferBackWhenTheLastReferenceGoes) {
  auto pool = std::make_shared<TexelPool>(1 << 20);
  Image image(16, 16, 3);
  const uint8_t* address = image.texels.data();
  std::shared_ptr<DecodedTile> tile = pool->makeTile({0, 1, 2, 3}, std::move(image));
  EXPECT_EQ(tile->id, (TileId{0, 1, 2, 3}));
  EXPECT_EQ(tile->texels.width_px, 16u);
  std::shared_ptr<const DecodedTile> renderer_copy = tile;
  tile.reset();
  EXPECT_EQ(pool->idleBytes(), 0u);  // still held
  renderer_copy.reset();
  EXPECT_EQ(pool->idleBytes(), 16u * 16 * 3);
  EXPECT_EQ(pool->take(16 * 16 * 3).data(), address);
}

TEST(TexelPool, OutlivesItsOwnerWhileTilesAreAlive) {
  std::shared_ptr<DecodedTile> tile;
  std::weak_ptr<TexelPool> weak;
  {
    auto pool = std::make_shared<TexelPool>(1 << 20);
    weak = pool;
    tile = pool->makeTile({0, 0, 0, 0}, Image(4, 4, 4));
  }
  EXPECT_FALSE(weak.expired());  // the tile keeps the pool its buffer goes back to
  tile.reset();
  EXPECT_TRUE(weak.expired());
}

}  // namespace
}  // namespace tessera::detail
