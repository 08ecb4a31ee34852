// The BrushDatabase interface on both backends: SQLite (always) and PostGIS (a throwaway cluster
// started by the suite; skipped with the reason when PostgreSQL or PostGIS is missing). Both
// must return the same instances, in the same order, for the same edits.
#include <tessera/brushes.h>

#include <algorithm>
#include <filesystem>

#include <gtest/gtest.h>
#include <sqlite3.h>

#include "brushes/postgres_cluster.h"
#include "procedural/procedural_fixtures.h"

namespace tessera {
namespace {

std::unique_ptr<testing::PostgresCluster>& cluster() {
  static std::unique_ptr<testing::PostgresCluster> instance;
  return instance;
}
std::string& clusterProblem() {
  static std::string problem;
  return problem;
}

class BrushDatabaseTest : public ::testing::TestWithParam<std::string> {
 public:
  static void SetUpTestSuite() { cluster() = testing::PostgresCluster::start(&clusterProblem()); }
  static void TearDownTestSuite() { cluster().reset(); }

 protected:
  void SetUp() override {
    static int counter = 0;
    ++counter;
    if (GetParam() == "postgis") {
      if (!cluster()) GTEST_SKIP() << "PostGIS tests skipped: " << clusterProblem();
      location_ = cluster()->createDatabase("t" + std::to_string(counter));
    } else {
      location_ = (std::filesystem::temp_directory_path() /
                   ("tessera-brushes-" + std::to_string(::getpid()) + "-" +
                    std::to_string(counter) + ".sqlite"))
                      .string();
      std::filesystem::remove(location_);
    }
    auto opened = openBrushDatabase(location_, true);
    ASSERT_TRUE(opened) << opened.error().message;
    db_ = std::move(*opened);
    EXPECT_STREQ(db_->backend(), GetParam().c_str());
  }
  void TearDown() override {
    db_.reset();
    if (GetParam() == "sqlite") {
      for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(location_ + suffix);
    }
  }

  void addTestBrushes() {
    for (const Brush& brush : testing::testBrushes()) {
      auto id = db_->addBrush(brush);
      ASSERT_TRUE(id) << id.error().message;
    }
  }

  std::string location_;
  std::unique_ptr<BrushDatabase> db_;
};

TEST_P(BrushDatabaseTest, BrushesRoundTripWithTheirImages) {
  addTestBrushes();
  auto brushes = db_->brushes();
  ASSERT_TRUE(brushes) << brushes.error().message;
  std::vector<Brush> expected = testing::testBrushes();
  ASSERT_EQ(brushes->size(), expected.size());
  for (size_t b = 0; b < expected.size(); ++b) {
    EXPECT_EQ((*brushes)[b].name, expected[b].name);
    EXPECT_EQ((*brushes)[b].blend, expected[b].blend);
    EXPECT_EQ((*brushes)[b].mask, expected[b].mask);
    EXPECT_EQ((*brushes)[b].mask_low, expected[b].mask_low);
    ASSERT_EQ((*brushes)[b].images.size(), expected[b].images.size());
    for (size_t v = 0; v < expected[b].images.size(); ++v)
      EXPECT_EQ((*brushes)[b].images[v].texels, expected[b].images[v].texels);
  }
  auto duplicate = db_->addBrush(expected[0]);
  ASSERT_FALSE(duplicate);
  EXPECT_NE(duplicate.error().message.find("base"), std::string::npos);
}

TEST_P(BrushDatabaseTest, TextureExtentIsStored) {
  ASSERT_TRUE(db_->setTextureExtent({4096, 2048}));
  auto extent = db_->textureExtent();
  ASSERT_TRUE(extent);
  EXPECT_EQ(extent->width_px, 4096u);
  EXPECT_EQ(extent->height_px, 2048u);
}

// The spatial query returns exactly the instances whose bounds meet the box, in drawing order:
// checked against a linear scan for many boxes.
TEST_P(BrushDatabaseTest, QueryEqualsALinearScanInDrawingOrder) {
  addTestBrushes();
  std::vector<BrushInstance> instances = testing::randomInstances(3000, 4000, 3000, 7, 11);
  auto ids = db_->addInstances(instances);
  ASSERT_TRUE(ids) << ids.error().message;
  ASSERT_EQ(ids->size(), instances.size());
  for (size_t i = 0; i < instances.size(); ++i) {
    EXPECT_EQ((*ids)[i], i + 1);
    instances[i].id = (*ids)[i];
  }
  std::mt19937 rng(3);
  for (int q = 0; q < 60; ++q) {
    double x = rng() % 4000, y = rng() % 3000, side = 1 + rng() % 600;
    BoxPx box{x, y, x + side, y + side};
    std::vector<BrushInstance> expected;
    for (const BrushInstance& instance : instances)
      if (instanceBounds(instance).intersects(box)) expected.push_back(instance);
    std::sort(expected.begin(), expected.end(), drawsBefore);
    std::vector<BrushInstance> found;
    ASSERT_TRUE(db_->query(box, found));
    ASSERT_EQ(found.size(), expected.size()) << q;
    for (size_t i = 0; i < found.size(); ++i) {
      EXPECT_EQ(found[i].id, expected[i].id);
      EXPECT_EQ(found[i].x_px, expected[i].x_px);
      EXPECT_EQ(found[i].radius_px, expected[i].radius_px);
      EXPECT_EQ(found[i].rotation_rad, expected[i].rotation_rad);
      EXPECT_EQ(found[i].tint_rgba, expected[i].tint_rgba);
      EXPECT_EQ(found[i].layer, expected[i].layer);
      EXPECT_EQ(found[i].variant, expected[i].variant);
    }
  }
}

TEST_P(BrushDatabaseTest, ABadInstanceAddsNothing) {
  addTestBrushes();
  std::vector<BrushInstance> instances = testing::randomInstances(50, 500, 500, 7, 1);
  instances[40].brush = 99;
  auto ids = db_->addInstances(instances);
  ASSERT_FALSE(ids);
  EXPECT_NE(ids.error().message.find("instance 40"), std::string::npos) << ids.error().message;
  instances[40].brush = 0;
  instances[45].radius_px = -1;
  EXPECT_FALSE(db_->addInstances(instances));
  EXPECT_EQ(*db_->instanceCount(), 0u);
}

TEST_P(BrushDatabaseTest, DeletesByIdAndByBoxAndLists) {
  addTestBrushes();
  std::vector<BrushInstance> instances = testing::randomInstances(200, 1000, 1000, 7, 2);
  ASSERT_TRUE(db_->addInstances(instances));
  const uint64_t to_delete[] = {1, 2, 3, 999};
  auto deleted = db_->deleteInstances(to_delete);
  ASSERT_TRUE(deleted) << deleted.error().message;
  EXPECT_EQ(*deleted, 3u);
  EXPECT_EQ(*db_->instanceCount(), 197u);
  BoxPx box{0, 0, 300, 300};
  std::vector<BrushInstance> inside;
  ASSERT_TRUE(db_->query(box, inside));
  auto in_box = db_->deleteInstancesIn(box);
  ASSERT_TRUE(in_box);
  EXPECT_EQ(*in_box, inside.size());
  inside.clear();
  ASSERT_TRUE(db_->query(box, inside));
  EXPECT_TRUE(inside.empty());
  std::vector<uint64_t> listed;
  ASSERT_TRUE(db_->forEachInstance([&](const BrushInstance& instance) {
    listed.push_back(instance.id);
    return true;
  }));
  EXPECT_EQ(listed.size(), *db_->instanceCount());
  EXPECT_TRUE(std::is_sorted(listed.begin(), listed.end()));
  // New ids continue after the largest.
  auto more = db_->addInstances({instances.data(), 1});
  ASSERT_TRUE(more);
  EXPECT_EQ((*more)[0], 201u);
}

INSTANTIATE_TEST_SUITE_P(Backends, BrushDatabaseTest, ::testing::Values("sqlite", "postgis"),
                         [](const auto& param_info) { return param_info.param; });

TEST(SqliteBrushDatabase, RejectsOtherFilesAndNewerSchemas) {
  std::string path = (std::filesystem::temp_directory_path() / "tessera-not-a-db.sqlite").string();
  {
    std::FILE* file = std::fopen(path.c_str(), "wb");
    std::fputs("this is not a database, only text that is long enough to look like a header", file);
    std::fclose(file);
  }
  auto garbage = openSqliteBrushDatabase(path, false);
  ASSERT_FALSE(garbage);
  EXPECT_NE(garbage.error().message.find(path), std::string::npos);
  std::filesystem::remove(path);
  EXPECT_FALSE(openSqliteBrushDatabase(path, false));  // missing, not created
  {
    auto created = openSqliteBrushDatabase(path, true);
    ASSERT_TRUE(created) << created.error().message;
  }
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  sqlite3_exec(db, "UPDATE tessera_meta SET value = '99' WHERE key = 'schema_version'", nullptr,
               nullptr, nullptr);
  sqlite3_close(db);
  auto newer = openSqliteBrushDatabase(path, false);
  ASSERT_FALSE(newer);
  EXPECT_EQ(newer.error().code, ErrorCode::kUnsupported);
  for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(path + suffix);
}

}  // namespace
}  // namespace tessera
