// The builder's atomic output: nothing is visible until commit, a discarded file leaves
// nothing behind, and commit replaces a previous file whole.
#include "output/output_file.h"

#include <filesystem>

#include <gtest/gtest.h>

#include "support/test_images.h"

namespace tessera::detail {
namespace {

std::vector<std::string> listDir(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(dir))
    names.push_back(entry.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

std::span<const uint8_t> asBytes(const std::string& text) {
  return {reinterpret_cast<const uint8_t*>(text.data()), text.size()};
}

TEST(TempFile, NothingIsVisibleBeforeCommitAndTheFileAppearsAfter) {
  std::string dir = test::testTempDir();
  std::string path = dir + "out.tess";
  auto file = TempFile::create(path);
  ASSERT_TRUE(file) << file.error().message;
  ASSERT_TRUE(file->pwrite(6, asBytes("world")));
  ASSERT_TRUE(file->pwrite(0, asBytes("hello ")));
  EXPECT_FALSE(std::filesystem::exists(path));
  std::vector<uint8_t> back(11);
  ASSERT_TRUE(file->pread(0, back));
  EXPECT_EQ(std::string(back.begin(), back.end()), "hello world");
  ASSERT_TRUE(file->commit());
  std::vector<uint8_t> bytes = test::readFileBytes(path);
  EXPECT_EQ(std::string(bytes.begin(), bytes.end()), "hello world");
  EXPECT_EQ(listDir(dir), std::vector<std::string>{"out.tess"});
}

TEST(TempFile, ADiscardedFileLeavesNothingBehind) {
  std::string dir = test::testTempDir();
  {
    auto file = TempFile::create(dir + "out.tess");
    ASSERT_TRUE(file);
    ASSERT_TRUE(file->pwrite(0, asBytes("partial")));
  }
  EXPECT_TRUE(listDir(dir).empty());
}

TEST(TempFile, CommitReplacesAPreviousFileWhole) {
  std::string dir = test::testTempDir();
  std::string path = dir + "out.tess";
  ASSERT_TRUE(test::writeFileBytes(path, std::vector<uint8_t>(1000, 'x')));
  auto file = TempFile::create(path);
  ASSERT_TRUE(file);
  ASSERT_TRUE(file->pwrite(0, asBytes("new")));
  EXPECT_EQ(test::readFileBytes(path).size(), 1000u);  // untouched until commit
  ASSERT_TRUE(file->commit());
  std::vector<uint8_t> bytes = test::readFileBytes(path);
  EXPECT_EQ(std::string(bytes.begin(), bytes.end()), "new");
  EXPECT_EQ(listDir(dir), std::vector<std::string>{"out.tess"});
}

TEST(TempFile, ADiscardedFileLeavesAPreviousFileUntouched) {
  std::string dir = test::testTempDir();
  std::string path = dir + "out.tess";
  ASSERT_TRUE(test::writeFileBytes(path, std::vector<uint8_t>(10, 'p')));
  {
    auto file = TempFile::create(path);
    ASSERT_TRUE(file);
    ASSERT_TRUE(file->pwrite(0, asBytes("replacement")));
  }
  EXPECT_EQ(test::readFileBytes(path), std::vector<uint8_t>(10, 'p'));
  EXPECT_EQ(listDir(dir), std::vector<std::string>{"out.tess"});
}

TEST(TempFile, AMovedFileIsOwnedOnce) {
  std::string dir = test::testTempDir();
  auto file = TempFile::create(dir + "out.tess");
  ASSERT_TRUE(file);
  {
    TempFile moved(std::move(*file));
    ASSERT_TRUE(moved.pwrite(0, asBytes("abc")));
    ASSERT_TRUE(moved.commit());
  }
  // The moved-from object's destructor must neither close nor remove anything.
  EXPECT_EQ(test::readFileBytes(dir + "out.tess").size(), 3u);
}

TEST(TempFile, AMissingDirectoryIsNotFoundNamingThePath) {
  std::string path = test::testTempDir() + "no/such/dir/out.tess";
  auto file = TempFile::create(path);
  ASSERT_FALSE(file);
  EXPECT_EQ(file.error().code, ErrorCode::kNotFound);
  EXPECT_NE(file.error().message.find(path), std::string::npos) << file.error().message;
}

TEST(TempFile, AParentThatIsAFileIsRejected) {
  std::string dir = test::testTempDir();
  ASSERT_TRUE(test::writeFileBytes(dir + "file", {1, 2, 3}));
  auto file = TempFile::create(dir + "file/out.tess");
  ASSERT_FALSE(file);
  EXPECT_NE(file.error().message.find("file/out.tess"), std::string::npos) << file.error().message;
  EXPECT_EQ(listDir(dir), std::vector<std::string>{"file"});
}

TEST(TempFile, ReadingPastTheWrittenEndFails) {
  auto file = TempFile::create(test::testTempDir() + "out.tess");
  ASSERT_TRUE(file);
  ASSERT_TRUE(file->pwrite(0, asBytes("abc")));
  std::vector<uint8_t> out(4);
  auto read = file->pread(0, out);
  ASSERT_FALSE(read);
  EXPECT_NE(read.error().message.find("out.tess"), std::string::npos);
}

TEST(TempFile, ARelativePathUsesTheCurrentDirectory) {
  std::string dir = test::testTempDir();
  std::filesystem::path previous = std::filesystem::current_path();
  std::filesystem::current_path(dir);
  {
    auto file = TempFile::create("relative.tess");
    EXPECT_TRUE(file) << file.error().message;
    if (file) {
      EXPECT_TRUE(file->pwrite(0, asBytes("r")));
      EXPECT_TRUE(file->commit());
    }
  }
  std::filesystem::current_path(previous);
  EXPECT_EQ(listDir(dir), std::vector<std::string>{"relative.tess"});
}

}  // namespace
}  // namespace tessera::detail
