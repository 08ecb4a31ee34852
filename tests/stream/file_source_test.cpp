#include <gtest/gtest.h>
#include <tessera/format.h>
TEST(FileSource, LevelCount) { EXPECT_EQ(tessera::levelCountFor(256, 256, 256), 1u); }
