// Mixed archives over HTTP (issue 29, item 6): a remote Archive fetches the section table, the
// brush set and instance pages by range from `tessera serve`'s archive endpoint and composites
// procedural tiles locally, through readTile and through the loader pool into the tile cache,
// equal to the local file; the server's Deep Zoom and XYZ endpoints serve composited tiles.
#include <algorithm>
#include <filesystem>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <tessera/archive.h>
#include <tessera/brushes.h>
#include <tessera/cache.h>
#include <tessera/open.h>
#include <tessera/procedural_build.h>
#include <tessera/serve.h>

#include "codecs/decode.h"
#include "procedural/procedural_fixtures.h"
#include "serve/serve_fixture.h"
#include "stream/loader_pool.h"

namespace tessera {
namespace {

constexpr uint32_t kWidth = 700, kHeight = 500, kTile = 128;

class ProceduralRemoteTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("tessera-procremote-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
    const std::string database = (dir_ / "world.sqlite").string();
    {
      auto db = openSqliteBrushDatabase(database, true);
      ASSERT_TRUE(db) << db.error().message;
      ASSERT_TRUE((*db)->setTextureExtent({kWidth, kHeight}));
      std::vector<Brush> brushes = testing::testBrushes();
      brushes.erase(brushes.begin() + 5, brushes.end());  // no masks: no base layer
      for (const Brush& brush : brushes) ASSERT_TRUE((*db)->addBrush(brush));
      ASSERT_TRUE((*db)->addInstances(
          testing::randomInstances(600, kWidth, kHeight, uint32_t(brushes.size()), 17)));
    }
    ProceduralBuildOptions o;
    o.database = database;
    o.output = path_ = (dir_ / "world.tess").string();
    o.tile_size_px = kTile;
    o.border_px = 1;
    o.codec = Codec::kZstd;
    o.small_instance_texels = 0;
    o.threads = 2;
    o.cost_texel_ns = 8;  // both kinds of tile
    auto report = buildProceduralArchive(o);
    ASSERT_TRUE(report) << report.error().message;
    ASSERT_GT(report->tiles_procedural, 0u);
    ASSERT_GT(report->tiles_baked, 0u);
    server_ = test::startServer({path_});
    ASSERT_NE(server_, nullptr);
    local_ = Archive::openFile(path_).value();
  }
  void TearDown() override {
    server_.reset();
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  std::string url() const {
    return "http://127.0.0.1:" + std::to_string(server_->port()) + "/world.tess";
  }
  std::vector<TileId> allTiles() const {
    std::vector<TileId> tiles;
    const ImageInfo& info = local_->images()[0];
    for (uint32_t level = 0; level < info.level_count; ++level)
      for (uint32_t y = 0; y < info.tilesY(level); ++y)
        for (uint32_t x = 0; x < info.tilesX(level); ++x) tiles.push_back({0, level, x, y});
    return tiles;
  }

  std::filesystem::path dir_;
  std::string path_;
  std::unique_ptr<TileServer> server_;
  std::shared_ptr<Archive> local_;
};

Image decodePng(const std::string& bytes, uint32_t width, uint32_t height, uint32_t channels) {
  Image out(width, height, channels);
  std::span<const uint8_t> payload(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
  Result<void> decoded = detail::decodeTile(Codec::kPng, payload, out);
  EXPECT_TRUE(decoded) << (decoded ? "" : decoded.error().message);
  return out;
}

TEST_F(ProceduralRemoteTest, RemoteArchiveCompositesLikeTheLocalFile) {
  auto remote = openArchive(url());
  ASSERT_TRUE(remote) << remote.error().message;
  uint64_t procedural = 0;
  for (const TileId& id : allTiles()) {
    auto entry = (*remote)->tileEntry(id);
    ASSERT_TRUE(entry) << entry.error().message;
    procedural += entry->kind == TileKind::kProcedural;
    Result<Image> a = (*remote)->readTile(id);
    Result<Image> b = local_->readTile(id);
    ASSERT_TRUE(a) << a.error().message;
    ASSERT_TRUE(b) << b.error().message;
    ASSERT_EQ(a->texels, b->texels) << "tile " << id.level << "," << id.x << "," << id.y;
  }
  EXPECT_GT(procedural, 0u);
  // The brush set came over the link by range, like every other block.
  auto tiles = (*remote)->procedural();
  ASSERT_TRUE(tiles) << tiles.error().message;
  EXPECT_GT((*tiles)->storedBrushBytes(), 0u);
  EXPECT_EQ((*remote)->source().linkStats()->errors, 0u);
}

// The streaming runtime's loader pool fetches instance pages with merged range reads and puts
// composited tiles into the same decoded-tile cache as decoded ones.
TEST_F(ProceduralRemoteTest, LoaderPoolCachesCompositedTilesFromARemoteArchive) {
  auto remote = openArchive(url());
  ASSERT_TRUE(remote) << remote.error().message;
  TileCache cache(size_t(64) << 20, makeLruPolicy());
  detail::LoaderOptions options;
  options.threads = 2;
  detail::LoaderPool pool(*remote, cache, options);
  std::vector<TileRequest> requests;
  uint64_t procedural = 0;
  for (const TileId& id : allTiles()) {
    requests.push_back({id, double(id.level), false, 1});
    procedural += local_->tileEntry(id)->kind == TileKind::kProcedural;
  }
  ASSERT_GT(procedural, 0u);
  pool.setWanted(requests);
  pool.waitIdle();
  std::vector<detail::LoadEvent> events;
  pool.poll(events);
  for (const detail::LoadEvent& event : events) EXPECT_TRUE(event.ok) << event.error;
  EXPECT_EQ(pool.stats().failures, 0u);
  for (const TileId& id : allTiles()) {
    auto cached = cache.find(id);
    ASSERT_TRUE(cached) << "tile " << id.level << "," << id.x << "," << id.y << " not cached";
    auto expected = local_->readTile(id);
    ASSERT_TRUE(expected);
    EXPECT_TRUE(cached->texels.texels == expected->texels)
        << "tile " << id.level << "," << id.x << "," << id.y;
  }
}

TEST_F(ProceduralRemoteTest, ServeSendsCompositedTilesToDeepZoomAndXyz) {
  const uint16_t port = server_->port();
  // Deep Zoom: 700 px -> max level 10 = level 0; 128-px tiles with 1 px of overlap.
  for (uint32_t row = 0; row < 4; ++row)
    for (uint32_t col = 0; col < 6; ++col) {
      const int64_t x0 = std::max<int64_t>(0, int64_t(col) * kTile - 1);
      const int64_t y0 = std::max<int64_t>(0, int64_t(row) * kTile - 1);
      const int64_t x1 = std::min<int64_t>(kWidth, int64_t(col + 1) * kTile + 1);
      const int64_t y1 = std::min<int64_t>(kHeight, int64_t(row + 1) * kTile + 1);
      const PixelRect rect{x0, y0, uint32_t(x1 - x0), uint32_t(y1 - y0)};
      test::HttpReply reply =
          test::httpRequest(port, fmt::format("/world/0_files/10/{}_{}.png", col, row));
      ASSERT_EQ(reply.status, 200u) << reply.body;
      Image expected = local_->readRegion(0, 0, rect).value();
      Image got = decodePng(reply.body, rect.width, rect.height, 4);
      EXPECT_EQ(got.texels, expected.texels) << col << "_" << row;
    }
  // XYZ: zmax = ceil(log2(700 / 256)) = 2, one pixel per level-0 pixel, padded transparent.
  for (uint32_t y = 0; y < 2; ++y)
    for (uint32_t x = 0; x < 3; ++x) {
      test::HttpReply reply =
          test::httpRequest(port, fmt::format("/world/0/xyz/2/{}/{}.png", x, y));
      ASSERT_EQ(reply.status, 200u) << reply.body;
      Image got = decodePng(reply.body, 256, 256, 4);
      const uint32_t w = std::min(256u, kWidth - x * 256), h = std::min(256u, kHeight - y * 256);
      Image inside = local_->readRegionRgba(0, 0, {x * 256, y * 256, w, h}).value();
      for (uint32_t py = 0; py < 256; ++py)
        for (uint32_t px = 0; px < 256; ++px)
          for (uint32_t c = 0; c < 4; ++c) {
            const uint8_t expected = px < w && py < h ? inside.row(py)[px * 4 + c] : 0;
            ASSERT_EQ(got.row(py)[px * 4 + c], expected) << x << "," << y << " " << px << "," << py;
          }
    }
  // The raw tile endpoint names the kind; ?format= composites.
  const TileId procedural_tile = [&] {
    for (const TileId& id : allTiles())
      if (local_->tileEntry(id)->kind == TileKind::kProcedural) return id;
    return TileId{};
  }();
  test::HttpReply raw =
      test::httpRequest(port, fmt::format("/world/0/{}/{}/{}", procedural_tile.level,
                                          procedural_tile.x, procedural_tile.y));
  EXPECT_EQ(raw.header("x-tessera-tile-kind"), "procedural");
}

}  // namespace
}  // namespace tessera
