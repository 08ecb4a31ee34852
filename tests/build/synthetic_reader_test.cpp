#include <gtest/gtest.h>
#include <tessera/format.h>
TEST(Synth, LevelCount) { EXPECT_EQ(tessera::levelCountFor(256, 256, 256), 1u); }
