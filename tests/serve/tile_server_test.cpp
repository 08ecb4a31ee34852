// The endpoints of docs/serve.md against an in-process server on an ephemeral port: stored
// tiles, the archive file with byte ranges, info documents, Deep Zoom, XYZ, transcoding,
// metrics, the viewer, CORS and the access log.
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <tessera/archive.h>
#include <tessera/display_window.h>
#include <tessera/serve.h>

#include "codecs/decode.h"
#include "serve/serve_fixture.h"
#include "support/test_images.h"
#include "support/wide_archive.h"

namespace tessera::test {
namespace {

std::string fileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream out;
  out << in.rdbuf();
  return out.str();
}

std::string pngArchive() {
  return servedArchive("pngb1", 1000, 700, 3, Codec::kPng, 128, 1);
}
std::string zstdArchive() {
  return servedArchive("zstd4", 600, 400, 4, Codec::kZstd, 64, 0);
}
std::string jpegArchive() {
  return servedArchive("jpeg3", 700, 500, 3, Codec::kJpeg, 256, 0);
}

Image decodePicture(Codec codec, const std::string& bytes, uint32_t width, uint32_t height,
                    uint32_t channels) {
  Image out(width, height, channels);
  std::span<const uint8_t> payload(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
  Result<void> decoded = detail::decodeTile(codec, payload, out);
  EXPECT_TRUE(decoded) << (decoded ? "" : decoded.error().message);
  return out;
}

class TileServerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    paths_ = {pngArchive(), zstdArchive(), jpegArchive()};
    server_ = startServer(paths_);
    ASSERT_NE(server_, nullptr);
    port_ = server_->port();
    png_ = Archive::openFile(paths_[0]).value();
    zstd_ = Archive::openFile(paths_[1]).value();
    jpeg_ = Archive::openFile(paths_[2]).value();
  }
  std::vector<std::string> paths_;
  std::unique_ptr<TileServer> server_;
  uint16_t port_ = 0;
  std::shared_ptr<Archive> png_, zstd_, jpeg_;
};

TEST_F(TileServerTest, HealthAndArchiveList) {
  HttpReply health = httpRequest(port_, "/healthz");
  EXPECT_EQ(health.status, 200u);
  EXPECT_EQ(health.body, "ok");
  HttpReply list = httpRequest(port_, "/api/archives");
  ASSERT_EQ(list.status, 200u);
  EXPECT_EQ(list.header("content-type"), "application/json");
  nlohmann::json doc = nlohmann::json::parse(list.body);
  ASSERT_EQ(doc["archives"].size(), 3u);
  EXPECT_EQ(doc["archives"][1]["name"], "pngb1");
  EXPECT_EQ(doc["archives"][1]["url"], "/pngb1.tess");
  EXPECT_EQ(doc["archives"][1]["info"], "/pngb1/info.json");
}

TEST_F(TileServerTest, InfoDocumentDescribesImagesAndLevels) {
  HttpReply reply = httpRequest(port_, "/pngb1/info.json");
  ASSERT_EQ(reply.status, 200u);
  nlohmann::json doc = nlohmann::json::parse(reply.body);
  EXPECT_EQ(doc["name"], "pngb1");
  EXPECT_EQ(doc["file_bytes"], png_->fileBytes());
  EXPECT_EQ(doc["etag"], reply.header("etag"));
  const ImageInfo& info = png_->images()[0];
  const nlohmann::json& image = doc["images"][0];
  EXPECT_EQ(image["width"], info.width_px);
  EXPECT_EQ(image["tile_size"], 128);
  EXPECT_EQ(image["border"], 1);
  EXPECT_EQ(image["codec"], "png");
  EXPECT_EQ(image["tile_content_type"], "image/png");
  EXPECT_EQ(image["level_count"], info.level_count);
  ASSERT_EQ(image["levels"].size(), info.level_count);
  EXPECT_EQ(image["levels"][1]["tiles_x"], info.tilesX(1));
  EXPECT_EQ(image["dzi"], "/pngb1/0.dzi");
  EXPECT_EQ(image["xyz"], "/pngb1/0/xyz/{z}/{x}/{y}.png");
  EXPECT_FALSE(image.contains("georeference"));  // a synthetic source has none
  EXPECT_EQ(httpRequest(port_, "/nope/info.json").status, 404u);
}

// A GeoTIFF source's georeference (tags and EPSG code) is in the image's info.json entry.
TEST(TileServerGeo, InfoDocumentCarriesTheGeoreference) {
  const std::string dir = testTempDir() + "/serve-geo/";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  TiffSpec spec{.width_px = 300, .height_px = 200, .samples = 3};
  spec.geo.model_pixel_scale = {0.5, 0.5, 0.0};
  spec.geo.model_tiepoint = {0, 0, 0, 440720.0, 3751320.0, 0};
  spec.geo.geo_key_directory = {1, 1, 0, 1, 3072, 0, 1, 26711};
  ASSERT_EQ(writeTiff(dir + "utm.tif", spec, makeTestPixels(300, 200, 3, 2)), "");
  BuildOptions build;
  build.inputs = {dir + "utm.tif"};
  build.output = dir + "utm.tess";
  Result<BuildReport> built = buildArchive(build);
  ASSERT_TRUE(built) << built.error().message;
  std::unique_ptr<TileServer> server = startServer({build.output});
  ASSERT_NE(server, nullptr);
  HttpReply reply = httpRequest(server->port(), "/utm/info.json");
  ASSERT_EQ(reply.status, 200u);
  const nlohmann::json geo = nlohmann::json::parse(reply.body)["images"][0]["georeference"];
  EXPECT_EQ(geo["epsg"], 26711);
  EXPECT_EQ(geo["model_tiepoint"], nlohmann::json(spec.geo.model_tiepoint));
  EXPECT_EQ(geo["model_pixel_scale"], nlohmann::json(spec.geo.model_pixel_scale));
  server.reset();
  std::filesystem::remove_all(dir);
}

TEST_F(TileServerTest, TileEndpointSendsTheStoredPayload) {
  const ImageInfo& info = zstd_->images()[0];
  for (uint32_t level = 0; level < info.level_count; ++level) {
    const TileId id{0, level, info.tilesX(level) - 1, info.tilesY(level) - 1};
    TileEntry entry = zstd_->tileEntry(id).value();
    HttpReply reply = httpRequest(port_, fmt::format("/zstd4/0/{}/{}/{}", level, id.x, id.y));
    if (entry.kind != TileKind::kEncoded) {
      EXPECT_EQ(reply.status, 204u);
      continue;
    }
    ASSERT_EQ(reply.status, 200u) << reply.body;
    std::vector<uint8_t> payload = zstd_->readPayload(id, entry).value();
    EXPECT_EQ(reply.body, std::string(payload.begin(), payload.end()));
    EXPECT_EQ(reply.header("content-type"), "application/octet-stream");
    EXPECT_EQ(reply.header("x-tessera-codec"), "zstd");
    EXPECT_EQ(reply.header("cache-control"), "public, max-age=31536000, immutable");
    EXPECT_FALSE(reply.header("etag").empty());
  }
  HttpReply jpeg = httpRequest(port_, "/jpeg3/0/0/1/1");
  ASSERT_EQ(jpeg.status, 200u);
  EXPECT_EQ(jpeg.header("content-type"), "image/jpeg");
  std::vector<uint8_t> payload =
      jpeg_->readPayload({0, 0, 1, 1}, jpeg_->tileEntry({0, 0, 1, 1}).value()).value();
  EXPECT_EQ(jpeg.body, std::string(payload.begin(), payload.end()));
}

// bc1 and bc7 tiles go out as stored, so that a browser offering S3TC or BPTC uploads them
// as they are (docs/web.md); info.json gives the side the blocks cover, padding included.
TEST(TileServerBlocks, BlockTilesAreTheStoredBlocksSizedByPayloadSide) {
  // Stored side 66: padded to 68, whole 4x4 blocks.
  const std::string path = servedArchive("bc1b1", 300, 200, 3, Codec::kBc1, 64, 1);
  std::shared_ptr<Archive> archive = Archive::openFile(path).value();
  std::unique_ptr<TileServer> server = startServer({path, pngArchive()});
  ASSERT_NE(server, nullptr);
  const uint16_t port = server->port();
  const nlohmann::json image =
      nlohmann::json::parse(httpRequest(port, "/bc1b1/info.json").body)["images"][0];
  EXPECT_EQ(image["codec"], "bc1");
  EXPECT_EQ(image["payload_side"], 68);
  EXPECT_EQ(nlohmann::json::parse(
                httpRequest(port, "/pngb1/info.json").body)["images"][0]["payload_side"],
            130);
  const ImageInfo& info = archive->images()[0];
  int encoded = 0;
  for (uint32_t y = 0; y < info.tilesY(0); ++y)
    for (uint32_t x = 0; x < info.tilesX(0); ++x) {
      const TileId id{0, 0, x, y};
      const TileEntry entry = archive->tileEntry(id).value();
      if (entry.kind != TileKind::kEncoded) continue;
      ++encoded;
      const std::string target = fmt::format("/bc1b1/0/0/{}/{}", x, y);
      HttpReply reply = httpRequest(port, target);
      ASSERT_EQ(reply.status, 200u) << target << ": " << reply.body;
      const std::vector<uint8_t> payload = archive->readPayload(id, entry).value();
      EXPECT_EQ(reply.body, std::string(payload.begin(), payload.end())) << target;
      EXPECT_EQ(reply.body.size(), (68u / 4) * (68u / 4) * 8) << target;
      EXPECT_EQ(reply.header("content-type"), "application/octet-stream");
      EXPECT_EQ(reply.header("x-tessera-codec"), "bc1");
      EXPECT_EQ(reply.header("cache-control"), "public, max-age=31536000, immutable");
      HttpReply head = httpRequest(port, target, {}, "HEAD");
      EXPECT_EQ(head.status, 200u);
      EXPECT_EQ(head.header("content-length"), std::to_string(payload.size()));
      EXPECT_TRUE(head.body.empty());
      EXPECT_EQ(head.header("etag"), reply.header("etag"));
      EXPECT_EQ(httpRequest(port, target, {{"If-None-Match", reply.header("etag")}}).status, 304u);
    }
  EXPECT_GT(encoded, 0);
}

TEST_F(TileServerTest, TileEtagAnswers304) {
  HttpReply first = httpRequest(port_, "/pngb1/0/0/2/3");
  ASSERT_EQ(first.status, 200u);
  HttpReply again = httpRequest(port_, "/pngb1/0/0/2/3", {{"If-None-Match", first.header("etag")}});
  EXPECT_EQ(again.status, 304u);
  EXPECT_TRUE(again.body.empty());
  EXPECT_EQ(again.header("etag"), first.header("etag"));
  HttpReply other = httpRequest(port_, "/pngb1/0/0/2/3", {{"If-None-Match", "\"other\""}});
  EXPECT_EQ(other.status, 200u);
}

TEST_F(TileServerTest, TileAddressesOutsideTheGridAre404AndMalformedOnes400) {
  const ImageInfo& info = png_->images()[0];
  EXPECT_EQ(httpRequest(port_, fmt::format("/pngb1/0/0/{}/0", info.tilesX(0))).status, 404u);
  EXPECT_EQ(httpRequest(port_, fmt::format("/pngb1/0/{}/0/0", info.level_count)).status, 404u);
  EXPECT_EQ(httpRequest(port_, "/pngb1/1/0/0/0").status, 404u);
  EXPECT_EQ(httpRequest(port_, "/pngb1/0/0/4294967295/4294967295").status, 404u);
  EXPECT_EQ(httpRequest(port_, "/pngb1/0/0/4294967296/0").status, 400u);
  EXPECT_EQ(httpRequest(port_, "/pngb1/0/0/99999999999999999999/0").status, 400u);
  EXPECT_EQ(httpRequest(port_, "/pngb1/0/0/-1/0").status, 400u);
  EXPECT_EQ(httpRequest(port_, "/pngb1/0/0/0x1/0").status, 400u);
  EXPECT_EQ(httpRequest(port_, "/pngb1/0/0/1/0?format=gif").status, 400u);
}

TEST_F(TileServerTest, TranscodedStoredTileHasTheDecodedTexels) {
  const ImageInfo& info = zstd_->images()[0];
  const TileId id{0, 1, 2, 1};
  HttpReply reply = httpRequest(port_, "/zstd4/0/1/2/1?format=png");
  ASSERT_EQ(reply.status, 200u) << reply.body;
  EXPECT_EQ(reply.header("content-type"), "image/png");
  Image expected = zstd_->readTile(id).value();
  Image got = decodePicture(Codec::kPng, reply.body, info.storedTileSidePx(),
                            info.storedTileSidePx(), info.channels);
  EXPECT_EQ(got.texels, expected.texels);
  HttpReply jpeg = httpRequest(port_, "/zstd4/0/1/2/1?format=jpeg");
  ASSERT_EQ(jpeg.status, 200u);
  EXPECT_EQ(jpeg.header("content-type"), "image/jpeg");
  // JPEG has no alpha: three channels, lossy.
  Image lossy =
      decodePicture(Codec::kJpeg, jpeg.body, info.storedTileSidePx(), info.storedTileSidePx(), 3);
  EXPECT_EQ(lossy.width_px, info.storedTileSidePx());
}

// ptm tiles are coded against their parents and no browser decodes them: the tile endpoint
// serves the stored residual as octet-stream, and `?format=png` and the DZI endpoint transcode
// the fully decoded texels (the archive decodes each tile's parent chain first).
TEST(TileServerPtm, TranscodesEveryTileOfAPtmArchiveToItsDecodedTexels) {
  const std::string path = servedArchive("ptm4", 300, 200, 4, Codec::kPtm, 64, 1);
  ASSERT_FALSE(path.empty());
  std::unique_ptr<TileServer> server = startServer({path});
  ASSERT_NE(server, nullptr);
  std::shared_ptr<Archive> archive = Archive::openFile(path).value();
  const ImageInfo& info = archive->images()[0];
  ASSERT_GE(info.level_count, 3u);
  // Finest level first, so the server meets children before their parents.
  for (uint32_t level = 0; level < info.level_count; ++level) {
    for (uint32_t y = 0; y < info.tilesY(level); ++y) {
      for (uint32_t x = 0; x < info.tilesX(level); ++x) {
        const TileId id{0, level, x, y};
        HttpReply reply =
            httpRequest(server->port(), fmt::format("/ptm4/0/{}/{}/{}?format=png", level, x, y));
        ASSERT_EQ(reply.status, 200u) << reply.body;
        Image got = decodePicture(Codec::kPng, reply.body, info.storedTileSidePx(),
                                  info.storedTileSidePx(), info.channels);
        EXPECT_EQ(got.texels, archive->readTile(id).value().texels)
            << "tile " << level << "," << x << "," << y;
      }
    }
  }
  const TileId fine{0, 0, 1, 1};
  const TileEntry entry = archive->tileEntry(fine).value();
  ASSERT_EQ(entry.kind, TileKind::kEncoded);
  HttpReply stored = httpRequest(server->port(), "/ptm4/0/0/1/1");
  ASSERT_EQ(stored.status, 200u);
  EXPECT_EQ(stored.header("content-type"), "application/octet-stream");
  EXPECT_EQ(stored.body.size(), entry.length_bytes);
  // DZI: 300 px -> max level 9 = tessera level 0; tile (0, 0) of 64 px with 1 px overlap.
  HttpReply dzi = httpRequest(server->port(), "/ptm4/0_files/9/0_0.png");
  ASSERT_EQ(dzi.status, 200u) << dzi.body;
  Image expected = archive->readRegion(0, 0, {0, 0, 65, 65}).value();
  EXPECT_EQ(decodePicture(Codec::kPng, dzi.body, 65, 65, info.channels).texels, expected.texels);
}

TEST_F(TileServerTest, ArchiveFileWholeAndHead) {
  const std::string bytes = fileBytes(paths_[0]);
  HttpReply whole = httpRequest(port_, "/pngb1.tess");
  ASSERT_EQ(whole.status, 200u);
  EXPECT_EQ(whole.body, bytes);
  EXPECT_EQ(whole.header("accept-ranges"), "bytes");
  EXPECT_FALSE(whole.header("last-modified").empty());
  HttpReply head = httpRequest(port_, "/pngb1.tess", {}, "HEAD");
  EXPECT_EQ(head.status, 200u);
  EXPECT_EQ(head.header("content-length"), std::to_string(bytes.size()));
  EXPECT_EQ(head.header("etag"), whole.header("etag"));
  EXPECT_EQ(httpRequest(port_, "/missing.tess").status, 404u);
}

TEST_F(TileServerTest, SingleRangeIs206WithContentRange) {
  const std::string bytes = fileBytes(paths_[0]);
  HttpReply reply = httpRequest(port_, "/pngb1.tess", {{"Range", "bytes=100-1099"}});
  ASSERT_EQ(reply.status, 206u);
  EXPECT_EQ(reply.body, bytes.substr(100, 1000));
  EXPECT_EQ(reply.header("content-range"), fmt::format("bytes 100-1099/{}", bytes.size()));
  HttpReply suffix = httpRequest(port_, "/pngb1.tess", {{"Range", "bytes=-10"}});
  ASSERT_EQ(suffix.status, 206u);
  EXPECT_EQ(suffix.body, bytes.substr(bytes.size() - 10));
}

TEST_F(TileServerTest, SeveralRangesAreMultipartByteranges) {
  const std::string bytes = fileBytes(paths_[0]);
  HttpReply reply = httpRequest(port_, "/pngb1.tess", {{"Range", "bytes=0-15,5000-5099,-7"}});
  ASSERT_EQ(reply.status, 206u);
  const std::string type = reply.header("content-type");
  ASSERT_TRUE(type.starts_with("multipart/byteranges; boundary=")) << type;
  const std::string boundary = type.substr(type.find('=') + 1);
  // Parse the parts back: each is headers, a blank line, then exactly the range's bytes.
  struct Expected {
    uint64_t first, length;
  };
  std::vector<Expected> expected = {{0, 16}, {5000, 100}, {bytes.size() - 7, 7}};
  size_t at = 0;
  for (const Expected& part : expected) {
    at = reply.body.find("--" + boundary + "\r\n", at);
    ASSERT_NE(at, std::string::npos);
    size_t headers_end = reply.body.find("\r\n\r\n", at);
    ASSERT_NE(headers_end, std::string::npos);
    std::string headers = reply.body.substr(at, headers_end - at);
    EXPECT_NE(headers.find(fmt::format("Content-Range: bytes {}-{}/{}", part.first,
                                       part.first + part.length - 1, bytes.size())),
              std::string::npos)
        << headers;
    EXPECT_EQ(reply.body.substr(headers_end + 4, part.length),
              bytes.substr(part.first, part.length));
    at = headers_end + 4 + part.length;
  }
  EXPECT_EQ(reply.body.substr(at), "\r\n--" + boundary + "--\r\n");
}

TEST_F(TileServerTest, UnsatisfiableAndTooManyRangesAre416) {
  const uint64_t size = std::filesystem::file_size(paths_[0]);
  HttpReply past = httpRequest(port_, "/pngb1.tess", {{"Range", fmt::format("bytes={}-", size)}});
  EXPECT_EQ(past.status, 416u);
  EXPECT_EQ(past.header("content-range"), fmt::format("bytes */{}", size));
  std::string many = "bytes=0-0";
  for (int i = 1; i <= 16; ++i) many += fmt::format(",{}-{}", i * 10, i * 10);
  HttpReply too_many = httpRequest(port_, "/pngb1.tess", {{"Range", many}});
  EXPECT_EQ(too_many.status, 416u);
  // Invalid syntax is ignored: the whole file.
  HttpReply invalid = httpRequest(port_, "/pngb1.tess", {{"Range", "bytes=9-3"}});
  EXPECT_EQ(invalid.status, 200u);
  EXPECT_EQ(invalid.body.size(), size);
}

TEST_F(TileServerTest, OverlappingRangesAreCoalesced) {
  const std::string bytes = fileBytes(paths_[0]);
  HttpReply reply = httpRequest(port_, "/pngb1.tess", {{"Range", "bytes=0-99,50-149,10-20"}});
  ASSERT_EQ(reply.status, 206u);
  EXPECT_EQ(reply.header("content-range"), fmt::format("bytes 0-149/{}", bytes.size()));
  EXPECT_EQ(reply.body, bytes.substr(0, 150));
}

TEST_F(TileServerTest, IfMatchOnTheArchiveFileRefusesAnyOtherVersion) {
  const std::string bytes = fileBytes(paths_[0]);
  const std::string etag = httpRequest(port_, "/pngb1.tess", {}, "HEAD").header("etag");
  HttpReply same = httpRequest(port_, "/pngb1.tess", {{"Range", "bytes=5-14"}, {"If-Match", etag}});
  EXPECT_EQ(same.status, 206u);
  EXPECT_EQ(same.body, bytes.substr(5, 10));
  HttpReply listed =
      httpRequest(port_, "/pngb1.tess", {{"Range", "bytes=5-14"}, {"If-Match", "\"x\", " + etag}});
  EXPECT_EQ(listed.status, 206u);
  HttpReply any = httpRequest(port_, "/pngb1.tess", {{"Range", "bytes=5-14"}, {"If-Match", "*"}});
  EXPECT_EQ(any.status, 206u);
  // Another version, or this one compared weakly: 412 and no bytes of the file.
  for (const std::string& other : {std::string("\"old\""), "W/" + etag}) {
    HttpReply refused =
        httpRequest(port_, "/pngb1.tess", {{"Range", "bytes=5-14"}, {"If-Match", other}});
    EXPECT_EQ(refused.status, 412u) << other;
    EXPECT_EQ(refused.header("etag"), etag);
    EXPECT_EQ(refused.body.find(bytes.substr(5, 10)), std::string::npos);
  }
}

TEST(TileServerChange, AnArchiveRewrittenInPlaceIsRefusedNotServedUnderItsOldEtag) {
  const std::string original = servedArchive("pngb1", 1000, 700, 3, Codec::kPng, 128, 1);
  const std::string path = ::testing::TempDir() + "/rewritten-in-place.tess";
  std::filesystem::copy_file(original, path, std::filesystem::copy_options::overwrite_existing);
  std::unique_ptr<TileServer> server = startServer({path});
  ASSERT_NE(server, nullptr);
  const uint16_t port = server->port();
  ASSERT_EQ(httpRequest(port, "/rewritten-in-place.tess", {{"Range", "bytes=0-9"}}).status, 206u);
  ASSERT_EQ(httpRequest(port, "/rewritten-in-place/0/0/0/0").status, 200u);
  {
    // Same inode, same size, new bytes and modification time: what an in-place rewrite does.
    std::fstream file(path, std::ios::binary | std::ios::in | std::ios::out);
    file.seekp(20000);
    file.put('\x5a');
  }
  const auto later = std::filesystem::last_write_time(path) + std::chrono::seconds(2);
  std::filesystem::last_write_time(path, later);
  for (const std::string& target :
       {std::string("/rewritten-in-place.tess"), std::string("/rewritten-in-place/0/0/0/0"),
        std::string("/rewritten-in-place/info.json")}) {
    HttpReply reply = httpRequest(port, target, {{"Range", "bytes=0-9"}});
    EXPECT_EQ(reply.status, 503u) << target;
    EXPECT_NE(reply.body.find("changed on disk"), std::string::npos) << reply.body;
  }
  EXPECT_EQ(httpRequest(port, "/healthz").status, 200u);
  server->stop();
  std::filesystem::remove(path);
}

TEST_F(TileServerTest, IfRangeAndIfNoneMatchOnTheArchiveFile) {
  const std::string bytes = fileBytes(paths_[0]);
  HttpReply head = httpRequest(port_, "/pngb1.tess", {}, "HEAD");
  const std::string etag = head.header("etag");
  HttpReply matching =
      httpRequest(port_, "/pngb1.tess", {{"Range", "bytes=0-9"}, {"If-Range", etag}});
  EXPECT_EQ(matching.status, 206u);
  HttpReply by_date = httpRequest(
      port_, "/pngb1.tess", {{"Range", "bytes=0-9"}, {"If-Range", head.header("last-modified")}});
  EXPECT_EQ(by_date.status, 206u);
  HttpReply stale =
      httpRequest(port_, "/pngb1.tess", {{"Range", "bytes=0-9"}, {"If-Range", "\"old\""}});
  EXPECT_EQ(stale.status, 200u);
  EXPECT_EQ(stale.body, bytes);
  HttpReply cached = httpRequest(port_, "/pngb1.tess", {{"If-None-Match", etag}});
  EXPECT_EQ(cached.status, 304u);
  EXPECT_TRUE(cached.body.empty());
}

TEST_F(TileServerTest, DziDescriptorNamesTileSizeOverlapAndFormat) {
  HttpReply reply = httpRequest(port_, "/pngb1/0.dzi");
  ASSERT_EQ(reply.status, 200u);
  EXPECT_NE(reply.body.find("TileSize=\"128\""), std::string::npos) << reply.body;
  EXPECT_NE(reply.body.find("Overlap=\"1\""), std::string::npos);
  EXPECT_NE(reply.body.find("Format=\"png\""), std::string::npos);
  EXPECT_NE(reply.body.find("<Size Width=\"1000\" Height=\"700\"/>"), std::string::npos);
  EXPECT_NE(httpRequest(port_, "/jpeg3/0.dzi").body.find("Format=\"jpg\""), std::string::npos);
  EXPECT_EQ(httpRequest(port_, "/pngb1/1.dzi").status, 404u);
}

TEST_F(TileServerTest, DziTilesAreTheArchiveRegionWithOverlapCroppedAtEdges) {
  // 1000 px -> DZI max level 10 = tessera level 0; tiles of 128 with 1 px overlap.
  struct Case {
    uint32_t dz_level, col, row;
    PixelRect rect;
  };
  const std::vector<Case> cases = {
      {10, 0, 0, {0, 0, 129, 129}},      // top-left: overlap only right and below
      {10, 2, 3, {255, 383, 130, 130}},  // interior: overlap on all four sides
      {10, 7, 5, {895, 639, 105, 61}},   // bottom-right: cropped to 1000 x 700
      {9, 3, 2, {383, 255, 117, 95}},    // level 1 (500 x 350)
  };
  for (const Case& c : cases) {
    HttpReply reply =
        httpRequest(port_, fmt::format("/pngb1/0_files/{}/{}_{}.png", c.dz_level, c.col, c.row));
    ASSERT_EQ(reply.status, 200u) << reply.body;
    EXPECT_EQ(reply.header("content-type"), "image/png");
    Image expected = png_->readRegion(0, 10 - c.dz_level, c.rect).value();
    Image got = decodePicture(Codec::kPng, reply.body, c.rect.width, c.rect.height, 3);
    EXPECT_EQ(got.texels, expected.texels) << c.dz_level << "/" << c.col << "_" << c.row;
  }
  EXPECT_EQ(httpRequest(port_, "/pngb1/0_files/10/8_0.png").status, 404u);
  EXPECT_EQ(httpRequest(port_, "/pngb1/0_files/11/0_0.png").status, 404u);
  EXPECT_EQ(httpRequest(port_, "/pngb1/0_files/10/0_0.gif").status, 404u);
  EXPECT_EQ(httpRequest(port_, "/pngb1/0_files/10/a_0.png").status, 400u);
}

TEST_F(TileServerTest, DziLevelsCoarserThanTheArchiveAreBoxFilteredFromItsCoarsest) {
  const ImageInfo& info = png_->images()[0];
  const uint32_t coarsest = info.level_count - 1;
  Image source = png_->readRegion(0, coarsest,
                                  {0, 0, info.levelWidthPx(coarsest), info.levelHeightPx(coarsest)})
                     .value();
  // DZI level 2 is 1000 / 2^8 -> 4 x 3 px; the archive's coarsest is level 3 (125 x 88).
  const uint32_t scale = 10 - 2, factor = 1u << (scale - coarsest);
  HttpReply reply = httpRequest(port_, "/pngb1/0_files/2/0_0.png");
  ASSERT_EQ(reply.status, 200u);
  Image got = decodePicture(Codec::kPng, reply.body, 4, 3, 3);
  for (uint32_t y = 0; y < 3; ++y)
    for (uint32_t x = 0; x < 4; ++x)
      for (uint32_t c = 0; c < 3; ++c) {
        uint64_t sum = 0, count = 0;
        for (uint32_t sy = y * factor; sy < std::min(source.height_px, (y + 1) * factor); ++sy)
          for (uint32_t sx = x * factor; sx < std::min(source.width_px, (x + 1) * factor); ++sx) {
            sum += source.row(sy)[sx * 3 + c];
            ++count;
          }
        EXPECT_EQ(got.row(y)[x * 3 + c], uint8_t((sum + count / 2) / count));
      }
  HttpReply single = httpRequest(port_, "/pngb1/0_files/0/0_0.png");
  ASSERT_EQ(single.status, 200u);
  decodePicture(Codec::kPng, single.body, 1, 1, 3);
}

TEST_F(TileServerTest, XyzTilesAreScaledRegionsPaddedWithTransparency) {
  // 600 x 400: zmax = ceil(log2(600 / 256)) = 2; at z = 2 one pixel is one level-0 pixel.
  HttpReply reply = httpRequest(port_, "/zstd4/0/xyz/2/2/1.png");
  ASSERT_EQ(reply.status, 200u) << reply.body;
  Image got = decodePicture(Codec::kPng, reply.body, 256, 256, 4);
  Image inside = zstd_->readRegionRgba(0, 0, {512, 256, 88, 144}).value();
  for (uint32_t y = 0; y < 256; ++y)
    for (uint32_t x = 0; x < 256; ++x)
      for (uint32_t c = 0; c < 4; ++c) {
        const uint8_t expected = x < 88 && y < 144 ? inside.row(y)[x * 4 + c] : 0;
        ASSERT_EQ(got.row(y)[x * 4 + c], expected) << x << "," << y << "," << c;
      }
  // z = 0: level 2 (150 x 100) in the top-left of one tile.
  HttpReply top = httpRequest(port_, "/zstd4/0/xyz/0/0/0.png");
  ASSERT_EQ(top.status, 200u);
  Image whole = decodePicture(Codec::kPng, top.body, 256, 256, 4);
  Image level2 = zstd_->readRegionRgba(0, 2, {0, 0, 150, 100}).value();
  EXPECT_EQ(std::vector<uint8_t>(whole.row(99), whole.row(99) + 150 * 4),
            std::vector<uint8_t>(level2.row(99), level2.row(99) + 150 * 4));
  EXPECT_EQ(whole.row(100)[0 * 4 + 3], 0);
  EXPECT_EQ(httpRequest(port_, "/zstd4/0/xyz/3/0/0.png").status, 404u);
  EXPECT_EQ(httpRequest(port_, "/zstd4/0/xyz/2/3/0.png").status, 404u);
  EXPECT_EQ(httpRequest(port_, "/zstd4/0/xyz/2/0/2.png").status, 404u);
}

TEST_F(TileServerTest, XyzTileOfAMatchingJpegArchiveIsTheStoredPayload) {
  // Tile size 256, no border, JPEG: an interior XYZ tile at zmax is a stored tile as is.
  const ImageInfo& info = jpeg_->images()[0];
  const uint32_t zmax = 2;  // ceil(log2(700 / 256))
  ASSERT_EQ(info.tile_size_px, 256u);
  HttpReply reply = httpRequest(port_, fmt::format("/jpeg3/0/xyz/{}/1/0.jpg", zmax));
  ASSERT_EQ(reply.status, 200u);
  std::vector<uint8_t> payload =
      jpeg_->readPayload({0, 0, 1, 0}, jpeg_->tileEntry({0, 0, 1, 0}).value()).value();
  EXPECT_EQ(reply.body, std::string(payload.begin(), payload.end()));
}

TEST_F(TileServerTest, MetricsCountRequestsBytesAndCache) {
  auto value = [&](const std::string& text, const std::string& series) -> double {
    size_t at = text.find("\n" + series + " ");
    if (at == std::string::npos) return -1;
    return std::stod(text.substr(at + series.size() + 2));
  };
  std::string before = httpRequest(port_, "/metrics").body;
  ASSERT_EQ(httpRequest(port_, "/pngb1/0/0/0/0").status, 200u);
  ASSERT_EQ(httpRequest(port_, "/pngb1/9/0/0/0").status, 404u);
  ASSERT_EQ(httpRequest(port_, "/zstd4/0/xyz/1/0/0.png").status, 200u);
  ASSERT_EQ(httpRequest(port_, "/zstd4/0/xyz/1/0/0.png").status, 200u);
  HttpReply after = httpRequest(port_, "/metrics");
  EXPECT_EQ(after.header("content-type"), "text/plain; version=0.0.4; charset=utf-8");
  const std::string& text = after.body;
  EXPECT_GE(value(text, "tessera_http_requests_total{endpoint=\"tile\",status=\"200\"}"), 1);
  EXPECT_GE(value(text, "tessera_http_requests_total{endpoint=\"tile\",status=\"404\"}"), 1);
  EXPECT_GT(value(text, "tessera_http_response_body_bytes_total"),
            value(before, "tessera_http_response_body_bytes_total"));
  EXPECT_GE(value(text, "tessera_transcode_cache_hits_total"),
            value(before, "tessera_transcode_cache_hits_total") + 1);
  EXPECT_GE(value(text, "tessera_transcode_cache_misses_total"),
            value(before, "tessera_transcode_cache_misses_total") + 1);
  EXPECT_GT(value(text, "tessera_http_request_duration_seconds_count"),
            value(before, "tessera_http_request_duration_seconds_count"));
  EXPECT_EQ(value(text, "tessera_http_request_duration_seconds_bucket{le=\"+Inf\"}"),
            value(text, "tessera_http_request_duration_seconds_count"));
}

TEST(TileServer, TranscodeCacheStaysWithinItsBudget) {
  ServeOptions options;
  options.transcode_cache_bytes = 40000;
  std::unique_ptr<TileServer> server = startServer({zstdArchive()}, options);
  ASSERT_NE(server, nullptr);
  for (uint32_t y = 0; y < 7; ++y)
    for (uint32_t x = 0; x < 10; ++x)
      ASSERT_EQ(
          httpRequest(server->port(), fmt::format("/zstd4/0/0/{}/{}?format=png", x, y)).status,
          200u);
  ServeStats stats = server->stats();
  EXPECT_LE(stats.transcode_cache_bytes, 40000u);
  EXPECT_GT(stats.transcode_cache_entries, 0u);
  EXPECT_LT(stats.transcode_cache_entries, 70u);
  EXPECT_EQ(stats.transcode_cache_misses, 70u);
  // The most recent tile is still cached.
  ASSERT_EQ(httpRequest(server->port(), "/zstd4/0/0/9/6?format=png").status, 200u);
  EXPECT_EQ(server->stats().transcode_cache_hits, 1u);
}

TEST_F(TileServerTest, ViewerFilesAreEmbedded) {
  HttpReply index = httpRequest(port_, "/");
  ASSERT_EQ(index.status, 200u);
  EXPECT_EQ(index.header("content-type"), "text/html; charset=utf-8");
  EXPECT_EQ(index.body, fileBytes(std::string(TESSERA_SOURCE_DIR) + "/web/viewer/index.html"));
  EXPECT_EQ(httpRequest(port_, "/viewer/index.html").body, index.body);
  EXPECT_EQ(httpRequest(port_, "/viewer/no-such-file.js").status, 404u);
}

TEST(TileServer, CorsHeadersAndPreflight) {
  ServeOptions options;
  options.cors_origin = "*";
  std::unique_ptr<TileServer> server = startServer({pngArchive()}, options);
  ASSERT_NE(server, nullptr);
  HttpReply tile = httpRequest(server->port(), "/pngb1/0/0/0/0");
  EXPECT_EQ(tile.header("access-control-allow-origin"), "*");
  EXPECT_NE(tile.header("access-control-expose-headers").find("Content-Range"), std::string::npos);
  HttpReply preflight = httpRequest(server->port(), "/pngb1.tess",
                                    {{"Origin", "http://example.org"},
                                     {"Access-Control-Request-Method", "GET"},
                                     {"Access-Control-Request-Headers", "range"}},
                                    "OPTIONS");
  EXPECT_EQ(preflight.status, 204u);
  EXPECT_NE(preflight.header("access-control-allow-headers").find("Range"), std::string::npos);
  EXPECT_NE(preflight.header("access-control-allow-methods").find("GET"), std::string::npos);
  // Without --cors no CORS header is sent.
  std::unique_ptr<TileServer> plain = startServer({pngArchive()});
  EXPECT_EQ(httpRequest(plain->port(), "/healthz").header("access-control-allow-origin"), "");
}

TEST(TileServer, AccessLogHasOneLinePerRequest) {
  ServeOptions options;
  options.access_log = std::filesystem::path(::testing::TempDir()) /
                       fmt::format("tessera_access_{}.log", ::getpid());
  std::filesystem::remove(options.access_log);
  std::unique_ptr<TileServer> server = startServer({pngArchive()}, options);
  ASSERT_NE(server, nullptr);
  httpRequest(server->port(), "/healthz");
  httpRequest(server->port(), "/pngb1/0/0/99/0");
  server->stop();
  std::ifstream in(options.access_log);
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  ASSERT_EQ(lines.size(), 2u);
  // time peer method target status bytes microseconds
  // Lines are written as responses finish, which need not be the order clients saw them.
  const std::string& line = lines[0].find("/99/") != std::string::npos ? lines[0] : lines[1];
  std::istringstream fields(line);
  std::string time, peer, method, target;
  unsigned status = 0;
  uint64_t bytes = 0, micros = 0;
  fields >> time >> peer >> method >> target >> status >> bytes >> micros;
  EXPECT_TRUE(time.ends_with("Z")) << line;
  EXPECT_TRUE(peer.starts_with("127.0.0.1:")) << line;
  EXPECT_EQ(method, "GET");
  EXPECT_EQ(target, "/pngb1/0/0/99/0");
  EXPECT_EQ(status, 404u);
  EXPECT_GT(bytes, 0u);
  std::filesystem::remove(options.access_log);
}

TEST(TileServer, StartFailsNamingTheProblem) {
  ServeOptions options;
  options.paths = {"/nonexistent/x.tess"};
  options.port = 0;
  Result<std::unique_ptr<TileServer>> missing = TileServer::start(options);
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().message.find("/nonexistent/x.tess"), std::string::npos);
  options.paths = {pngArchive(), pngArchive()};
  Result<std::unique_ptr<TileServer>> twice = TileServer::start(options);
  ASSERT_FALSE(twice);
  EXPECT_NE(twice.error().message.find("already served"), std::string::npos);
  options.paths = {pngArchive()};
  options.bind_address = "not-an-address";
  EXPECT_FALSE(TileServer::start(options));
}

TEST(TileServer, CorruptPayloadIs500NamingTheTile) {
  // A copy of an archive with one payload byte flipped: the checksum catches it.
  const std::string source = pngArchive();
  const std::string damaged =
      (std::filesystem::path(source).parent_path() / "damaged.tess").string();
  std::filesystem::copy_file(source, damaged, std::filesystem::copy_options::overwrite_existing);
  std::shared_ptr<Archive> archive = Archive::openFile(source).value();
  const TileEntry entry = archive->tileEntry({0, 0, 1, 1}).value();
  ASSERT_EQ(entry.kind, TileKind::kEncoded);
  {
    std::fstream file(damaged, std::ios::in | std::ios::out | std::ios::binary);
    file.seekg(std::streamoff(entry.offset_bytes + entry.length_bytes / 2));
    char byte = 0;
    file.read(&byte, 1);
    byte = char(byte ^ 0x5a);
    file.seekp(std::streamoff(entry.offset_bytes + entry.length_bytes / 2));
    file.write(&byte, 1);
  }
  std::unique_ptr<TileServer> server = startServer({damaged});
  ASSERT_NE(server, nullptr);
  HttpReply reply = httpRequest(server->port(), "/damaged/0/0/1/1");
  EXPECT_EQ(reply.status, 500u);
  // The message names the archive by its public name and the tile; the server's path stays
  // private.
  EXPECT_NE(reply.body.find("damaged.tess: tile (0,1,1) checksum mismatch"), std::string::npos)
      << reply.body;
  EXPECT_EQ(reply.body.find(damaged), std::string::npos) << reply.body;
  EXPECT_EQ(httpRequest(server->port(), "/damaged/0_files/10/1_1.png").status, 500u);
  // Other tiles are still served.
  EXPECT_EQ(httpRequest(server->port(), "/damaged/0/0/0/0").status, 200u);
  const std::string metrics = httpRequest(server->port(), "/metrics").body;
  EXPECT_NE(metrics.find("tessera_http_errors_total{kind=\"archive\"} 2"), std::string::npos);
  std::filesystem::remove(damaged);
}

TEST(TileServer, OnListeningReportsTheBoundPortOnce) {
  ServeOptions options;
  int calls = 0;
  uint16_t reported = 0;
  std::string address;
  options.on_listening = [&](const std::string& bound, uint16_t port) {
    ++calls;
    address = bound;
    reported = port;
  };
  std::unique_ptr<TileServer> server = startServer({pngArchive()}, options);
  ASSERT_NE(server, nullptr);
  EXPECT_EQ(calls, 1);
  EXPECT_EQ(address, "127.0.0.1");
  EXPECT_EQ(reported, server->port());
  EXPECT_NE(reported, 0);
}

TEST(TileServer, FolderServesEveryArchiveInside) {
  const std::string path = pngArchive();
  std::unique_ptr<TileServer> server =
      startServer({std::filesystem::path(path).parent_path().string()});
  ASSERT_NE(server, nullptr);
  std::vector<std::string> names = server->archiveNames();
  EXPECT_NE(std::find(names.begin(), names.end(), "pngb1"), names.end());
  EXPECT_EQ(httpRequest(server->port(), "/pngb1/info.json").status, 200u);
}

// A u16 archive's stored tile as an 8-bit picture: each texel is the window formula of its
// sample; the NaN-free u16 case keeps every pixel opaque. Bad window and gamma values are
// 400s naming the parameter.
TEST(WideTiles, PicturesOfU16TilesFollowTheWindowInTheQuery) {
  auto sampleAt = [](uint32_t x, uint32_t y) { return uint16_t(x * 1000 + y * 7); };
  const std::string archive_path = testTempDir() + "wide16.tess";
  ASSERT_TRUE(buildWideArchive(archive_path, 64, 64, 1, SampleType::kU16,
                               [&](uint32_t x, uint32_t y, uint32_t) { return sampleAt(x, y); }));
  auto server = startServer({archive_path});
  ASSERT_TRUE(server);
  const uint16_t port = server->port();

  HttpReply info = httpRequest(port, "/wide16/info.json");
  ASSERT_EQ(info.status, 200u);
  const nlohmann::json image_info = nlohmann::json::parse(info.body)["images"][0];
  EXPECT_EQ(image_info["sample_type"], "u16");
  EXPECT_LT(image_info["display_window"]["low"], image_info["display_window"]["high"]);
  // The native tile: the stored zstd payload.
  EXPECT_EQ(httpRequest(port, "/wide16/0/0/0/0").header("x-tessera-codec"), "zstd");

  const DisplayWindow window{5000, 40000, 0.5};
  HttpReply reply = httpRequest(port, "/wide16/0/0/0/0?format=png&window=5000,40000&gamma=0.5");
  // The stored tile, the Deep Zoom tile of the full-size level and the XYZ tile of the deepest
  // zoom hold the same 64 x 64 texels.
  const std::string query = "?window=5000,40000&gamma=0.5";
  HttpReply dzi = httpRequest(port, "/wide16/0_files/6/0_0.png" + query);
  HttpReply xyz = httpRequest(port, "/wide16/0/xyz/0/0/0.png" + query);
  for (const auto& [picture, side] :
       {std::pair{&reply, 64u}, std::pair{&dzi, 64u}, std::pair{&xyz, 256u}}) {
    ASSERT_EQ(picture->status, 200u) << picture->body;
    Image got = decodePicture(Codec::kPng, picture->body, side, side, 4);
    uint32_t wrong = 0;
    for (uint32_t y = 0; y < 64; ++y)
      for (uint32_t x = 0; x < 64; ++x) {
        const uint8_t* p = got.texels.data() + (size_t(y) * side + x) * 4;
        const uint8_t want = windowSample(sampleAt(x, y), window);
        wrong += p[0] != want || p[1] != want || p[2] != want || p[3] != 255;
      }
    EXPECT_EQ(wrong, 0u) << side;
  }
  // Another window is another picture.
  HttpReply other = httpRequest(port, "/wide16/0/0/0/0?format=png&window=0,1000");
  ASSERT_EQ(other.status, 200u);
  EXPECT_NE(other.body, reply.body);
  // The default window comes from the statistics: a picture, not an error.
  EXPECT_EQ(httpRequest(port, "/wide16/0/0/0/0?format=png").status, 200u);
  // Percentiles resolved once serve every route after: the same window, the same picture.
  HttpReply first = httpRequest(port, "/wide16/0/0/0/0?format=png&window=p0,p100");
  HttpReply again = httpRequest(port, "/wide16/0_files/6/0_0.png?window=p0,p100");
  ASSERT_EQ(first.status, 200u);
  ASSERT_EQ(again.status, 200u);
  EXPECT_EQ(decodePicture(Codec::kPng, first.body, 64, 64, 4).texels,
            decodePicture(Codec::kPng, again.body, 64, 64, 4).texels);

  for (const char* bad : {"window=5", "window=9,2", "window=a,b", "window=p1,200"})
    for (const std::string path : {"/wide16/0/0/0/0?format=png&", "/wide16/0_files/6/0_0.png?",
                                   "/wide16/0/xyz/0/0/0.png?"}) {
      HttpReply refused = httpRequest(port, path + bad);
      EXPECT_EQ(refused.status, 400u) << path << bad;
      EXPECT_NE(refused.body.find("window"), std::string::npos) << refused.body;
    }
  for (const char* bad : {"gamma=0", "gamma=-1", "gamma=x", "gamma=nan"}) {
    HttpReply refused = httpRequest(port, std::string("/wide16/0/0/0/0?format=png&") + bad);
    EXPECT_EQ(refused.status, 400u) << bad;
    EXPECT_NE(refused.body.find("gamma"), std::string::npos) << refused.body;
  }
}

}  // namespace
}  // namespace tessera::test
