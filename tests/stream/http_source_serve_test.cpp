// The HTTP byte source against `tessera serve`'s archive endpoint (GET /<name>.tess with byte
// ranges, docs/serve.md), the server running in this process on an ephemeral port.
#include <tessera/http_source.h>
#include <tessera/open.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <thread>

#include <gtest/gtest.h>

#include <tessera/archive.h>
#include <tessera/serve.h>

#include "support/synthetic_archive.h"

namespace tessera {
namespace {

class ServeTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("tessera-http-serve-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
    test::SyntheticArchiveSpec spec;
    spec.codec = Codec::kJpeg;
    spec.width_px = 2048;
    spec.height_px = 1536;
    bytes_ = test::syntheticArchiveBytes(spec);
    ASSERT_FALSE(bytes_.empty());
    path_ = (dir_ / "earth.tess").string();
    std::ofstream(path_, std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes_.data()), std::streamsize(bytes_.size()));
    ServeOptions options;
    options.paths = {path_};
    options.port = 0;
    options.threads = 2;
    auto server = TileServer::start(options);
    ASSERT_TRUE(server) << server.error().message;
    server_ = std::move(*server);
    url_ = "http://127.0.0.1:" + std::to_string(server_->port()) + "/earth.tess";
  }
  void TearDown() override {
    server_.reset();
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  std::filesystem::path dir_;
  std::string path_, url_;
  std::vector<uint8_t> bytes_;
  std::unique_ptr<TileServer> server_;
};

TEST_F(ServeTest, ConcurrentRangeReadsEqualTheArchiveBytes) {
  auto source = openHttpSource(url_);
  ASSERT_TRUE(source) << source.error().message;
  EXPECT_EQ((*source)->sizeBytes(), bytes_.size());
  std::atomic<int> mismatches{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&, t] {
      std::mt19937 random(40 + t);
      for (int i = 0; i < 30; ++i) {
        const uint64_t offset = random() % bytes_.size();
        const size_t length = 1 + random() % std::min<uint64_t>(50000, bytes_.size() - offset);
        std::vector<uint8_t> out(length);
        Result<void> read = (*source)->read(offset, out);
        if (!read) ADD_FAILURE() << read.error().message;
        if (!read || !std::equal(out.begin(), out.end(), bytes_.begin() + ptrdiff_t(offset)))
          ++mismatches;
      }
    });
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(mismatches.load(), 0);
  EXPECT_EQ((*source)->linkStats()->errors, 0u);
  // readMany: scattered ranges, several merged, all sent at once.
  std::vector<std::vector<uint8_t>> outs(12);
  std::vector<ByteRange> ranges;
  for (size_t i = 0; i < outs.size(); ++i) {
    outs[i].resize(1000 + i * 300);
    ranges.push_back({(i * 7919 * 13) % (bytes_.size() - 5000), outs[i].size(), outs[i].data()});
  }
  ASSERT_TRUE((*source)->readMany(ranges));
  for (size_t i = 0; i < outs.size(); ++i)
    EXPECT_TRUE(std::equal(outs[i].begin(), outs[i].end(),
                           bytes_.begin() + ptrdiff_t(ranges[i].offset_bytes)))
        << i;
}

TEST_F(ServeTest, FarApartRangesTravelInOneMultiRangeRequestAndEachGetsItsOwnBytes) {
  HttpOptions options;
  options.max_ranges_per_request = 4;
  auto source = openHttpSource(url_, options);
  ASSERT_TRUE(source) << source.error().message;
  // Random lengths, each range more than readMany's 64 KiB merge gap from the next, so every
  // range is its own run; the bytes around each are checked untouched (no neighbour's bytes).
  std::mt19937 random(17);
  std::vector<std::vector<uint8_t>> outs;
  std::vector<ByteRange> ranges;
  for (uint64_t offset = 20000; offset + 70000 < bytes_.size() && outs.size() < 10;
       offset += 70000 + random() % 5000) {
    outs.emplace_back(1 + random() % 4000 + 2, uint8_t(0xA5));
    ranges.push_back({offset, outs.back().size() - 2, outs.back().data() + 1});
  }
  ASSERT_GE(ranges.size(), 5u) << "archive too small for the test: " << bytes_.size();
  const uint64_t before = (*source)->linkStats()->requests;
  ASSERT_TRUE((*source)->readMany(ranges));
  const uint64_t expected_requests = (ranges.size() + 3) / 4;
  EXPECT_EQ((*source)->linkStats()->requests - before, expected_requests);
  for (size_t i = 0; i < ranges.size(); ++i) {
    EXPECT_EQ(outs[i].front(), 0xA5) << i;
    EXPECT_EQ(outs[i].back(), 0xA5) << i;
    EXPECT_TRUE(std::equal(outs[i].begin() + 1, outs[i].end() - 1,
                           bytes_.begin() + ptrdiff_t(ranges[i].offset_bytes)))
        << i;
  }
  EXPECT_EQ((*source)->linkStats()->errors, 0u);
}

TEST_F(ServeTest, ArchiveOpensInTwoRequestsAndDecodesAsTheLocalFile) {
  auto remote = openArchive(url_);
  ASSERT_TRUE(remote) << remote.error().message;
  auto local = Archive::openFile(path_);
  ASSERT_TRUE(local);
  // The header region, then the whole directory (small here) read ahead.
  EXPECT_EQ((*remote)->source().linkStats()->requests, 2u);
  uint64_t payloads = 0;
  for (const TileId& id : test::allTiles(**local)) {
    Result<Image> a = (*remote)->readTile(id);
    Result<Image> b = (*local)->readTile(id);
    ASSERT_TRUE(a) << a.error().message;
    ASSERT_TRUE(b);
    ASSERT_EQ(a->texels, b->texels) << "tile " << id.level << "," << id.x << "," << id.y;
    payloads += (*local)->tileEntry(id)->hasPayload() ? 1 : 0;
  }
  // No directory page was read again: one request per payload.
  EXPECT_EQ((*remote)->source().linkStats()->requests, 2u + payloads);
}

TEST_F(ServeTest, UnknownArchiveIsNotFound) {
  const std::string url = "http://127.0.0.1:" + std::to_string(server_->port()) + "/moon.tess";
  auto source = openHttpSource(url);
  ASSERT_FALSE(source);
  EXPECT_EQ(source.error().code, ErrorCode::kNotFound);
  EXPECT_NE(source.error().message.find(url + ": bytes=0-16383: HTTP 404"), std::string::npos)
      << source.error().message;
}

// `tessera serve --access`: a protected archive opens with its bearer token (also from
// TESSERA_TOKEN through openArchive), not without; a signed URL that expired is renewed
// through HttpOptions::renew_url once and the source goes on with the new URL.
TEST_F(ServeTest, TokensAndRenewedSignedUrlsOpenAProtectedArchive) {
  const std::string token = "a-bearer-token-for-earth-0123";
  const std::string access = (dir_ / "access.json").string();
  std::ofstream(access) << R"({"tokens": [{"token": ")" << token
                        << R"(", "archives": ["earth"]}], "signing_keys": [{"id": "web",
                        "secret": "0123456789abcdef0123456789abcdef-web", "archives": ["*"]}]})";
  server_.reset();
  ServeOptions options;
  options.paths = {path_};
  options.port = 0;
  options.access_file = access;
  auto server = TileServer::start(options);
  ASSERT_TRUE(server) << server.error().message;
  server_ = std::move(*server);
  const std::string base = "http://127.0.0.1:" + std::to_string(server_->port());
  const std::string url = base + "/earth.tess";

  auto refused = openHttpSource(url);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("401"), std::string::npos) << refused.error().message;
  EXPECT_NE(refused.error().message.find("bearer token"), std::string::npos);

  HttpOptions with_token;
  with_token.bearer_token = token;
  auto source = openHttpSource(url, with_token);
  ASSERT_TRUE(source) << source.error().message;
  std::vector<uint8_t> tail(1000);
  ASSERT_TRUE((*source)->read(bytes_.size() - tail.size(), tail));
  EXPECT_TRUE(std::equal(tail.begin(), tail.end(), bytes_.end() - ptrdiff_t(tail.size())));
  EXPECT_EQ(refused.error().message.find(token), std::string::npos);

  ::setenv("TESSERA_TOKEN", token.c_str(), 1);
  auto archive = openArchive(url);
  ::unsetenv("TESSERA_TOKEN");
  ASSERT_TRUE(archive) << archive.error().message;

  const int64_t now = std::chrono::duration_cast<std::chrono::seconds>(
                          std::chrono::system_clock::now().time_since_epoch())
                          .count();
  auto expired = signServeQuery(access, "web", "/earth.tess", now - 10);
  ASSERT_TRUE(expired) << expired.error().message;
  std::vector<std::string> renewals;
  HttpOptions renewing;
  renewing.renew_url = [&](const std::string& refused_url) {
    renewals.push_back(refused_url);
    Result<std::string> fresh = signServeQuery(access, "web", "/earth.tess", now + 600);
    return fresh ? url + "?" + *fresh : std::string();
  };
  auto signed_source = openHttpSource(url + "?" + *expired, renewing);
  ASSERT_TRUE(signed_source) << signed_source.error().message;
  ASSERT_EQ(renewals.size(), 1u);
  EXPECT_EQ(renewals[0], url + "?" + *expired);
  ASSERT_TRUE((*signed_source)->read(bytes_.size() - tail.size(), tail));
  EXPECT_TRUE(std::equal(tail.begin(), tail.end(), bytes_.end() - ptrdiff_t(tail.size())));
  EXPECT_EQ(renewals.size(), 1u) << "later requests use the renewed URL";

  // A renewal that gives nothing fails the open with the 403.
  HttpOptions giving_up;
  giving_up.renew_url = [](const std::string&) { return std::string(); };
  auto gave_up = openHttpSource(url + "?" + *expired, giving_up);
  ASSERT_FALSE(gave_up);
  EXPECT_NE(gave_up.error().message.find("403"), std::string::npos) << gave_up.error().message;
}

}  // namespace
}  // namespace tessera
