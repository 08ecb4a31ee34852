// The HTTP byte source against nginx serving files statically (started on loopback by the
// test) and against a fault-injecting range server (tests/support/range_server.h).
#include <tessera/http_source.h>
#include <tessera/open.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <thread>

#include <curl/curl.h>
#include <gtest/gtest.h>

#include <tessera/archive.h>

#include "support/nginx_server.h"
#include "support/range_server.h"
#include "support/synthetic_archive.h"

namespace tessera {
namespace {

std::vector<uint8_t> randomBytes(size_t size, uint32_t seed) {
  std::mt19937 random(seed);
  std::vector<uint8_t> bytes(size);
  for (uint8_t& b : bytes) b = uint8_t(random());
  return bytes;
}

void writeFile(const std::string& path, const std::vector<uint8_t>& bytes) {
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}

std::vector<uint8_t> readRange(const ByteSource& source, uint64_t offset, size_t length) {
  std::vector<uint8_t> out(length);
  Result<void> read = source.read(offset, out);
  EXPECT_TRUE(read) << read.error().message;
  return out;
}

std::vector<uint8_t> slice(const std::vector<uint8_t>& bytes, uint64_t offset, size_t length) {
  return {bytes.begin() + ptrdiff_t(offset), bytes.begin() + ptrdiff_t(offset + length)};
}

/// Options for tests: fast retries, so fault tests take milliseconds.
HttpOptions quickOptions() {
  HttpOptions options;
  options.retry_initial = std::chrono::milliseconds(1);
  options.retry_max = std::chrono::milliseconds(5);
  options.retry_after_max = std::chrono::milliseconds(20);
  options.max_attempts = 3;
  return options;
}

class NginxTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!test::NginxServer::available())
      GTEST_SKIP() << test::NginxServer::kBinary
                   << " is not installed (scripts/install-deps.sh installs nginx-light)";
    dir_ = std::filesystem::temp_directory_path() /
           ("tessera-http-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_ / "www");
    bytes_ = randomBytes(3 << 20, 7);
    writeFile((dir_ / "www" / "data.bin").string(), bytes_);
    auto server = test::NginxServer::start((dir_ / "www").string(), (dir_ / "nginx").string());
    ASSERT_TRUE(server) << server.error().message;
    nginx_ = std::move(*server);
  }
  void TearDown() override {
    nginx_.reset();
    std::error_code ec;
    if (!dir_.empty()) std::filesystem::remove_all(dir_, ec);
  }

  std::shared_ptr<ByteSource> open(const std::string& url, const HttpOptions& options = {}) {
    auto source = openHttpSource(url, options);
    EXPECT_TRUE(source) << source.error().message;
    return source ? *source : nullptr;
  }

  std::filesystem::path dir_;
  std::vector<uint8_t> bytes_;
  std::unique_ptr<test::NginxServer> nginx_;
};

TEST_F(NginxTest, ReadsEqualTheFileAtRandomRanges) {
  auto source = open(nginx_->url("data.bin"));
  ASSERT_TRUE(source);
  EXPECT_EQ(source->sizeBytes(), bytes_.size());
  EXPECT_EQ(source->name(), nginx_->url("data.bin"));
  std::mt19937 random(1);
  for (int i = 0; i < 60; ++i) {
    const uint64_t offset = random() % bytes_.size();
    const size_t length = 1 + random() % std::min<uint64_t>(300000, bytes_.size() - offset);
    ASSERT_EQ(readRange(*source, offset, length), slice(bytes_, offset, length))
        << "offset " << offset << " length " << length;
  }
  // The last byte and a past-the-end range.
  EXPECT_EQ(readRange(*source, bytes_.size() - 1, 1), slice(bytes_, bytes_.size() - 1, 1));
  std::vector<uint8_t> out(2);
  Result<void> past = source->read(bytes_.size() - 1, out);
  ASSERT_FALSE(past);
  EXPECT_NE(past.error().message.find("past the end"), std::string::npos);
}

TEST_F(NginxTest, OpenIsOneRequestAndItsBytesServeTheFirstReads) {
  auto source = open(nginx_->url("data.bin"));
  ASSERT_TRUE(source);
  EXPECT_EQ(source->linkStats()->requests, 1u);
  EXPECT_EQ(readRange(*source, 100, 16000), slice(bytes_, 100, 16000));
  EXPECT_EQ(source->linkStats()->requests, 1u);
  EXPECT_EQ(readRange(*source, 16000, 1000), slice(bytes_, 16000, 1000));
  EXPECT_EQ(source->linkStats()->requests, 2u);
}

TEST_F(NginxTest, ConcurrentReadsShareKeepAliveConnections) {
  auto source = open(nginx_->url("data.bin"));
  ASSERT_TRUE(source);
  Result<uint64_t> accepted_before = nginx_->acceptedConnections();
  ASSERT_TRUE(accepted_before) << accepted_before.error().message;
  constexpr int kThreads = 6, kReads = 40;
  std::atomic<int> mismatches{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t)
    threads.emplace_back([&, t] {
      std::mt19937 random(100 + t);
      for (int i = 0; i < kReads; ++i) {
        const uint64_t offset = random() % (bytes_.size() - 70000);
        const size_t length = 1 + random() % 65536;
        std::vector<uint8_t> out(length);
        if (!source->read(offset, out) || out != slice(bytes_, offset, length)) ++mismatches;
      }
    });
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(mismatches.load(), 0);
  Result<uint64_t> accepted_after = nginx_->acceptedConnections();
  ASSERT_TRUE(accepted_after);
  // 240 requests over at most max_connections (8) connections, plus the status request.
  EXPECT_LE(*accepted_after - *accepted_before, HttpOptions{}.max_connections + 1);
  const LinkStats stats = *source->linkStats();
  EXPECT_EQ(stats.requests, 1u + kThreads * kReads);
  EXPECT_EQ(stats.errors, 0u);
  EXPECT_EQ(stats.retries, 0u);
  EXPECT_GE(stats.bytes_received, uint64_t(kThreads * kReads));
  EXPECT_EQ(stats.recent.size(), 64u);
  for (const LinkSample& sample : stats.recent) {
    EXPECT_GT(sample.bytes, 0u);
    EXPECT_GE(sample.seconds, sample.first_byte_seconds);
  }
}

// Reads from several threads over HTTPS, where nginx offers h2 by ALPN: all are streams of
// the open's one connection.
TEST_F(NginxTest, HttpsWithHttp2MultiplexesOneConnection) {
  if (nginx_->httpsUrl("").empty()) GTEST_SKIP() << "no /usr/bin/openssl to make a certificate";
  HttpOptions options;
  options.verify_tls = false;  // the test's self-signed certificate
  auto source = open(nginx_->httpsUrl("data.bin"), options);
  ASSERT_TRUE(source);
  Result<uint64_t> before = nginx_->acceptedConnections();
  ASSERT_TRUE(before);
  std::vector<std::thread> threads;
  std::atomic<int> mismatches{0};
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&, t] {
      std::mt19937 random(7 + t);
      for (int i = 0; i < 25; ++i) {
        const uint64_t offset = random() % (bytes_.size() - 40000);
        const size_t length = 1 + random() % 32768;
        std::vector<uint8_t> out(length);
        Result<void> read = source->read(offset, out);
        if (!read) ADD_FAILURE() << read.error().message;
        if (!read || out != slice(bytes_, offset, length)) ++mismatches;
      }
    });
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(mismatches.load(), 0);
  Result<uint64_t> after = nginx_->acceptedConnections();
  ASSERT_TRUE(after);
  // Only the status request made a new connection (nginx counts every port's together).
  EXPECT_EQ(*after - *before, 1u);
}

// The HTTP/2 path for real: nginx with TLS (its certificate checked, as the CA file) and h2
// offered by ALPN, against the same server with HTTP/1.1 only; the client reports which
// version each connection spoke, and both give the file's bytes.
TEST_F(NginxTest, HttpsOverHttp2AndHttp11GiveTheSameBytes) {
  if (nginx_->httpsUrl("").empty()) GTEST_SKIP() << "no /usr/bin/openssl to make a certificate";
  std::mt19937 random(11);
  std::vector<std::pair<uint64_t, size_t>> ranges;
  for (int i = 0; i < 30; ++i)
    ranges.emplace_back(random() % (bytes_.size() - 70000), 1 + random() % 65536);
  for (const bool http2 : {true, false}) {
    HttpOptions options;
    options.ca_file = nginx_->certificateFile();
    options.http2 = http2;
    auto source = open(nginx_->httpsUrl("data.bin"), options);
    ASSERT_TRUE(source);
    std::vector<std::thread> threads;
    std::atomic<int> mismatches{0};
    for (int t = 0; t < 3; ++t)
      threads.emplace_back([&, t] {
        for (size_t i = size_t(t); i < ranges.size(); i += 3)
          if (readRange(*source, ranges[i].first, ranges[i].second) !=
              slice(bytes_, ranges[i].first, ranges[i].second))
            ++mismatches;
      });
    for (std::thread& thread : threads) thread.join();
    EXPECT_EQ(mismatches.load(), 0) << "http2 " << http2;
    const LinkStats stats = *source->linkStats();
    EXPECT_GE(stats.connections, 1u);
    EXPECT_EQ(stats.http2_connections, http2 ? stats.connections : 0u);
    EXPECT_EQ(stats.http1_connections, http2 ? 0u : stats.connections);
  }
  // The tools' way: the CA file from the environment; without it the certificate is refused.
  ::setenv("TESSERA_CA_FILE", nginx_->certificateFile().c_str(), 1);
  Result<std::shared_ptr<ByteSource>> trusted = openByteSource(nginx_->httpsUrl("data.bin"));
  ::unsetenv("TESSERA_CA_FILE");
  EXPECT_TRUE(trusted) << trusted.error().message;
  EXPECT_FALSE(openByteSource(nginx_->httpsUrl("data.bin")));
}

// h2c needs libcurl 8: 7.88 fails every request on a reused prior-knowledge connection
// (curl/curl#10634), so the source refuses the option there instead of failing each read.
TEST_F(NginxTest, Http2PriorKnowledgeWorksOrIsRefusedClearly) {
  HttpOptions options;
  options.http2_prior_knowledge = true;
  auto opened = openHttpSource(nginx_->h2cUrl("data.bin"), options);
  if (curl_version_info(CURLVERSION_NOW)->version_num < 0x080000) {
    ASSERT_FALSE(opened);
    EXPECT_EQ(opened.error().code, ErrorCode::kUnsupported);
    EXPECT_NE(opened.error().message.find("libcurl 8"), std::string::npos);
    return;
  }
  ASSERT_TRUE(opened) << opened.error().message;
  for (int i = 0; i < 20; ++i)
    EXPECT_EQ(readRange(**opened, 20000 + i * 1000, 777), slice(bytes_, 20000 + i * 1000, 777));
}

TEST_F(NginxTest, ReadManyAndPrefetchDeliverTheFileBytes) {
  auto source = open(nginx_->url("data.bin"));
  ASSERT_TRUE(source);
  std::mt19937 random(3);
  std::vector<std::vector<uint8_t>> outs(40);
  std::vector<ByteRange> ranges;
  for (auto& out : outs) {
    const uint64_t offset = random() % (bytes_.size() - 20000);
    out.resize(1 + random() % 20000);
    ranges.push_back({offset, out.size(), out.data()});
  }
  ranges.push_back({5, 10, nullptr});  // overlapping the head, zero-copy
  std::vector<uint8_t> head(10);
  ranges.back().out = head.data();
  Result<void> read = source->readMany(ranges);
  ASSERT_TRUE(read) << read.error().message;
  for (size_t i = 0; i < outs.size(); ++i)
    EXPECT_EQ(outs[i], slice(bytes_, ranges[i].offset_bytes, outs[i].size())) << i;
  EXPECT_EQ(head, slice(bytes_, 5, 10));

  // Fetched ahead: the reads inside the hinted ranges make no request of their own.
  std::vector<ByteRange> hints = {{1 << 20, 200000, nullptr}, {2 << 20, 100000, nullptr}};
  const uint64_t requests = source->linkStats()->requests;
  EXPECT_EQ(source->prefetch(hints), 300000u);
  EXPECT_EQ(readRange(*source, (1 << 20) + 5000, 60000), slice(bytes_, (1 << 20) + 5000, 60000));
  EXPECT_EQ(readRange(*source, 2 << 20, 100000), slice(bytes_, 2 << 20, 100000));
  const LinkStats stats = *source->linkStats();
  EXPECT_EQ(stats.requests, requests + 2);  // the two fetch-aheads only
  EXPECT_EQ(stats.prefetch_hit_bytes, 160000u);
  EXPECT_EQ(stats.prefetched_bytes, 300000u);
  // The buffer is bounded: hints beyond it are not fetched.
  HttpOptions small;
  small.prefetch_buffer_bytes = 100000;
  auto bounded = open(nginx_->url("data.bin"), small);
  ASSERT_TRUE(bounded);
  EXPECT_EQ(bounded->prefetch(hints), 100000u);
}

/// `count` ranges of random lengths, each more than readMany's 64 KiB merge gap from the next.
std::vector<ByteRange> farApartRanges(std::vector<std::vector<uint8_t>>& outs, size_t count,
                                      uint64_t first, uint64_t step, uint32_t seed) {
  std::mt19937 random(seed);
  outs.assign(count, {});
  std::vector<ByteRange> ranges;
  for (size_t i = 0; i < count; ++i) {
    outs[i].resize(1 + random() % 3000);
    ranges.push_back({first + i * step, outs[i].size(), outs[i].data()});
  }
  return ranges;
}

TEST_F(NginxTest, FarApartRangesTravelInOneMultiRangeRequest) {
  auto source = open(nginx_->url("data.bin"));
  ASSERT_TRUE(source);
  std::vector<std::vector<uint8_t>> outs;
  const std::vector<ByteRange> ranges = farApartRanges(outs, 12, 100000, 200000, 5);
  const uint64_t before = source->linkStats()->requests;
  Result<void> read = source->readMany(ranges);
  ASSERT_TRUE(read) << read.error().message;
  EXPECT_EQ(source->linkStats()->requests - before, 1u);
  for (size_t i = 0; i < outs.size(); ++i)
    EXPECT_EQ(outs[i], slice(bytes_, ranges[i].offset_bytes, outs[i].size())) << i;
}

TEST_F(NginxTest, ArchiveOverHttpDecodesAsTheLocalFile) {
  test::SyntheticArchiveSpec spec;
  spec.codec = Codec::kJpeg;
  const std::vector<uint8_t>& archive_bytes = test::syntheticArchiveBytes(spec);
  ASSERT_FALSE(archive_bytes.empty());
  writeFile((dir_ / "www" / "x.tess").string(), archive_bytes);
  auto remote = openArchive(nginx_->url("x.tess"));
  ASSERT_TRUE(remote) << remote.error().message;
  auto local = Archive::openFile((dir_ / "www" / "x.tess").string());
  ASSERT_TRUE(local);
  // The header region, root directory and metadata of a small archive are in the first
  // 16 KiB: the open's first request; its directory pages, read ahead, the second.
  EXPECT_EQ((*remote)->source().linkStats()->requests, 2u);
  EXPECT_EQ((*remote)->images().size(), (*local)->images().size());
  for (const TileId& id : test::allTiles(**local)) {
    Result<Image> a = (*remote)->readTile(id);
    Result<Image> b = (*local)->readTile(id);
    ASSERT_TRUE(a) << a.error().message;
    ASSERT_TRUE(b);
    ASSERT_EQ(a->texels, b->texels) << "tile " << id.level << "," << id.x << "," << id.y;
  }
  EXPECT_TRUE((*remote)->verify().ok());
}

TEST_F(NginxTest, ChangedFileFailsClearlyAndNeverMixesVersions) {
  const std::string path = (dir_ / "www" / "data.bin").string();
  auto source = open(nginx_->url("data.bin"));
  ASSERT_TRUE(source);
  EXPECT_EQ(readRange(*source, 100000, 5000), slice(bytes_, 100000, 5000));
  // Same size, other bytes, another mtime: nginx's ETag changes.
  const auto mtime = std::filesystem::last_write_time(path);
  writeFile(path, randomBytes(bytes_.size(), 8));
  std::filesystem::last_write_time(path, mtime + std::chrono::seconds(10));
  std::vector<uint8_t> out(5000);
  Result<void> read = source->read(100000, out);
  ASSERT_FALSE(read);
  EXPECT_EQ(read.error().code, ErrorCode::kCorrupt);
  EXPECT_NE(read.error().message.find("archive changed on the server (ETag was \""),
            std::string::npos)
      << read.error().message;
  EXPECT_NE(read.error().message.find(", now \""), std::string::npos) << read.error().message;
  EXPECT_NE(read.error().message.find(nginx_->url("data.bin")), std::string::npos);
  // Every later read fails the same way, prefetches are refused, the head bytes too are
  // of the old version only while nothing else is asked.
  Result<void> again = source->read(2 << 20, out);
  ASSERT_FALSE(again);
  EXPECT_EQ(again.error().message, read.error().message);
  std::vector<ByteRange> hints = {{1 << 20, 1000, nullptr}};
  EXPECT_EQ(source->prefetch(hints), 0u);
  // A new open sees the new version.
  auto reopened = open(nginx_->url("data.bin"));
  ASSERT_TRUE(reopened);
  EXPECT_EQ(readRange(*reopened, 100000, 5000), slice(randomBytes(bytes_.size(), 8), 100000, 5000));
}

TEST_F(NginxTest, ServerThatIgnoresRangesIsRejected) {
  auto source = openHttpSource(nginx_->url("noranges/data.bin"));
  ASSERT_FALSE(source);
  EXPECT_EQ(source.error().code, ErrorCode::kUnsupported);
  EXPECT_NE(source.error().message.find("server does not honour byte ranges"), std::string::npos)
      << source.error().message;
  EXPECT_NE(source.error().message.find("noranges/data.bin"), std::string::npos);
}

TEST_F(NginxTest, MissingFileIsNotFoundWithoutRetries) {
  auto source = openHttpSource(nginx_->url("nothing.tess"), quickOptions());
  ASSERT_FALSE(source);
  EXPECT_EQ(source.error().code, ErrorCode::kNotFound);
  EXPECT_NE(source.error().message.find("nothing.tess: bytes=0-16383: HTTP 404"), std::string::npos)
      << source.error().message;
  EXPECT_EQ(source.error().message.find("attempts"), std::string::npos);
}

TEST_F(NginxTest, UnavailableServerFailsAfterItsAttempts) {
  auto source = openHttpSource(nginx_->url("unavailable/data.bin"), quickOptions());
  ASSERT_FALSE(source);
  EXPECT_EQ(source.error().code, ErrorCode::kIo);
  EXPECT_NE(source.error().message.find("HTTP 503"), std::string::npos) << source.error().message;
  EXPECT_NE(source.error().message.find("after 3 attempts"), std::string::npos)
      << source.error().message;
}

TEST(HttpSourceTest, ConnectionRefusedNamesTheUrl) {
  const uint16_t port = test::freeLoopbackPort();
  const std::string url = "http://127.0.0.1:" + std::to_string(port) + "/x.tess";
  auto source = openHttpSource(url, quickOptions());
  ASSERT_FALSE(source);
  EXPECT_EQ(source.error().code, ErrorCode::kIo);
  EXPECT_NE(source.error().message.find(url), std::string::npos) << source.error().message;
  EXPECT_NE(source.error().message.find("after 3 attempts"), std::string::npos);
}

TEST(HttpSourceTest, NotAUrlIsInvalidArgument) {
  auto source = openHttpSource("/tmp/x.tess");
  ASSERT_FALSE(source);
  EXPECT_EQ(source.error().code, ErrorCode::kInvalidArgument);
  EXPECT_TRUE(isRemoteUri("HTTPS://example.org/a.tess"));
  EXPECT_TRUE(isRemoteUri("http://h/a"));
  EXPECT_FALSE(isRemoteUri("httpx://h/a"));
  EXPECT_FALSE(isRemoteUri("http.tess"));
  auto file = openByteSource("/nonexistent/x.tess");
  ASSERT_FALSE(file);
  EXPECT_EQ(file.error().code, ErrorCode::kNotFound);
}

// ---- Against the fault-injecting server ----

class FaultTest : public ::testing::Test {
 protected:
  FaultTest() : bytes_(randomBytes(200000, 11)), server_(bytes_, "\"v1\"") {}

  std::shared_ptr<ByteSource> open(const HttpOptions& options = quickOptions()) {
    auto source = openHttpSource(server_.url(), options);
    EXPECT_TRUE(source) << source.error().message;
    return source ? *source : nullptr;
  }

  std::vector<uint8_t> bytes_;
  test::RangeServer server_;
};

TEST_F(FaultTest, ReadsSendTheVersionAsIfMatchAndIfRange) {
  auto source = open();
  ASSERT_TRUE(source);
  EXPECT_EQ(readRange(*source, 50000, 100), slice(bytes_, 50000, 100));
  std::vector<test::SeenRequest> seen = server_.seen();
  ASSERT_EQ(seen.size(), 2u);
  EXPECT_EQ(seen[0].range, "bytes=0-16383");
  EXPECT_EQ(seen[0].if_match, "");
  EXPECT_EQ(seen[1].range, "bytes=50000-50099");
  EXPECT_EQ(seen[1].if_match, "\"v1\"");
  EXPECT_EQ(seen[1].if_range, "\"v1\"");
}

TEST(HttpSourceTest, WithoutAnEtagReadsSendIfUnmodifiedSince) {
  const std::vector<uint8_t> bytes = randomBytes(50000, 2);
  test::RangeServer server(bytes, "");
  auto source = openHttpSource(server.url(), quickOptions());
  ASSERT_TRUE(source) << source.error().message;
  EXPECT_EQ(readRange(**source, 40000, 10), slice(bytes, 40000, 10));
  const auto seen = server.seen();
  ASSERT_EQ(seen.size(), 2u);
  EXPECT_EQ(seen[1].if_unmodified_since, "Mon, 23 Nov 2026 10:00:00 GMT");
  EXPECT_EQ(seen[1].if_match, "");
}

TEST_F(FaultTest, TransientErrorsAreRetriedThenSucceed) {
  HttpOptions options = quickOptions();
  options.max_attempts = 4;
  auto source = open(options);
  ASSERT_TRUE(source);
  // Requests 1 to 3 (after the open) fail: a 503 with Retry-After far beyond the cap (the
  // read would take 100 s if it were not capped), a 429, a 503 with a Retry-After date in
  // the past (retry at once).
  server_.setPlan([](uint64_t n) {
    if (n == 1) return test::RangeReply{test::RangeReply::Kind::kStatus, 503, "100"};
    if (n == 2) return test::RangeReply{test::RangeReply::Kind::kStatus, 429, "1"};
    if (n == 3)
      return test::RangeReply{test::RangeReply::Kind::kStatus, 503,
                              "Wed, 21 Oct 2015 07:28:00 GMT"};
    return test::RangeReply{};
  });
  const auto started = std::chrono::steady_clock::now();
  EXPECT_EQ(readRange(*source, 30000, 5000), slice(bytes_, 30000, 5000));
  EXPECT_LT(std::chrono::steady_clock::now() - started, std::chrono::seconds(50));
  const LinkStats stats = *source->linkStats();
  EXPECT_EQ(stats.retries, 3u);
  EXPECT_EQ(stats.requests, 5u);
  EXPECT_EQ(stats.errors, 0u);
}

TEST_F(FaultTest, ClientErrorsAreNotRetried) {
  auto source = open();
  ASSERT_TRUE(source);
  server_.setPlan([](uint64_t n) {
    return n >= 1 ? test::RangeReply{test::RangeReply::Kind::kStatus, 403, ""} : test::RangeReply{};
  });
  std::vector<uint8_t> out(10);
  Result<void> read = source->read(20000, out);
  ASSERT_FALSE(read);
  EXPECT_NE(read.error().message.find("bytes=20000-20009: HTTP 403"), std::string::npos)
      << read.error().message;
  EXPECT_EQ(read.error().code, ErrorCode::kIo);
  EXPECT_EQ(server_.seen().size(), 2u);
  EXPECT_EQ(source->linkStats()->retries, 0u);
  EXPECT_EQ(source->linkStats()->errors, 1u);
}

TEST_F(FaultTest, TruncatedResponsesAreRetriedAndReportedWhenTheyPersist) {
  auto source = open();
  ASSERT_TRUE(source);
  server_.setPlan([](uint64_t n) {
    return n == 1 ? test::RangeReply{test::RangeReply::Kind::kTruncate} : test::RangeReply{};
  });
  EXPECT_EQ(readRange(*source, 20000, 30000), slice(bytes_, 20000, 30000));
  EXPECT_EQ(source->linkStats()->retries, 1u);

  server_.setPlan([](uint64_t n) {
    return n >= 1 ? test::RangeReply{test::RangeReply::Kind::kTruncate} : test::RangeReply{};
  });
  std::vector<uint8_t> out(30000);
  Result<void> read = source->read(20000, out);
  ASSERT_FALSE(read);
  EXPECT_EQ(read.error().code, ErrorCode::kIo);
  EXPECT_NE(read.error().message.find("truncated response"), std::string::npos)
      << read.error().message;
  EXPECT_NE(read.error().message.find("after 3 attempts"), std::string::npos);
}

TEST_F(FaultTest, WrongContentRangeIsRejected) {
  auto source = open();
  ASSERT_TRUE(source);
  server_.setPlan([](uint64_t n) {
    return n >= 1 ? test::RangeReply{test::RangeReply::Kind::kWrongRange} : test::RangeReply{};
  });
  std::vector<uint8_t> out(100);
  Result<void> read = source->read(20000, out);
  ASSERT_FALSE(read);
  EXPECT_NE(read.error().message.find("bytes=20000-20099: server answered bytes 20001-20100"),
            std::string::npos)
      << read.error().message;
}

TEST_F(FaultTest, ServerThatStopsHonouringRangesIsRejectedWithoutDownloadingTheFile) {
  auto source = open();
  ASSERT_TRUE(source);
  server_.setPlan([](uint64_t n) {
    return n >= 1 ? test::RangeReply{test::RangeReply::Kind::kWholeFile} : test::RangeReply{};
  });
  std::vector<uint8_t> out(100);
  Result<void> read = source->read(20000, out);
  ASSERT_FALSE(read);
  EXPECT_EQ(read.error().code, ErrorCode::kUnsupported);
  EXPECT_NE(read.error().message.find("server does not honour byte ranges"), std::string::npos);
}

TEST_F(FaultTest, NewVersionBehindAServerIgnoringConditionalsIsDetected) {
  auto source = open();
  ASSERT_TRUE(source);
  std::vector<uint8_t> changed = bytes_;
  changed[20050] ^= 0xff;
  server_.replace(changed, "\"v2\"", /*honour_conditionals=*/false);
  std::vector<uint8_t> out(100);
  Result<void> read = source->read(20000, out);
  ASSERT_FALSE(read);
  EXPECT_EQ(read.error().code, ErrorCode::kCorrupt);
  EXPECT_NE(
      read.error().message.find("archive changed on the server (ETag was \"v1\", now \"v2\")"),
      std::string::npos)
      << read.error().message;
}

TEST_F(FaultTest, NewVersionAnswers412AndTheMessageNamesBothVersions) {
  auto source = open();
  ASSERT_TRUE(source);
  server_.replace(bytes_, "\"v3\"", /*honour_conditionals=*/true);
  std::vector<uint8_t> out(100);
  Result<void> read = source->read(20000, out);
  ASSERT_FALSE(read);
  EXPECT_NE(read.error().message.find("(ETag was \"v1\", now \"v3\")"), std::string::npos)
      << read.error().message;
}

TEST_F(FaultTest, CancelAbortsATransferInFlight) {
  auto source = open();
  ASSERT_TRUE(source);
  server_.setPlan([](uint64_t n) {
    return n == 1 ? test::RangeReply{test::RangeReply::Kind::kStall} : test::RangeReply{};
  });
  std::atomic<bool> cancel{false};
  Result<void> result;
  std::vector<uint8_t> out(150000);
  std::thread reader([&] { result = source->readCancellable(40000, out, cancel); });
  // Half the range has arrived and the server holds the rest: the transfer is in flight.
  server_.waitStalled();
  cancel.store(true, std::memory_order_release);
  reader.join();
  ASSERT_FALSE(result);
  EXPECT_EQ(result.error().code, ErrorCode::kCancelled);
  EXPECT_NE(result.error().message.find("bytes=40000-189999"), std::string::npos);
  EXPECT_EQ(source->linkStats()->cancelled, 1u);
  // The source goes on serving.
  EXPECT_EQ(readRange(*source, 40000, 1000), slice(bytes_, 40000, 1000));
  // A flag already set never sends a request.
  const size_t requests = server_.seen().size();
  Result<void> early = source->readCancellable(40000, out, cancel);
  EXPECT_EQ(early.error().code, ErrorCode::kCancelled);
  EXPECT_EQ(server_.seen().size(), requests);
}

TEST_F(FaultTest, CancelStopsAReaderWaitingForFetchedAheadBytes) {
  auto source = open();
  ASSERT_TRUE(source);
  server_.setPlan([](uint64_t n) {
    return n == 1 ? test::RangeReply{test::RangeReply::Kind::kStall} : test::RangeReply{};
  });
  std::vector<ByteRange> hints = {{50000, 100000, nullptr}};
  ASSERT_EQ(source->prefetch(hints), 100000u);
  server_.waitStalled();
  // The read lies inside the hinted range, whose transfer is stalled: it would wait forever
  // but for its flag (seen before or while it waits). The source then closes with that
  // fetch still in flight.
  std::atomic<bool> cancel{false};
  Result<void> result;
  std::vector<uint8_t> out(1000);
  std::thread reader([&] { result = source->readCancellable(60000, out, cancel); });
  cancel.store(true, std::memory_order_release);
  reader.join();
  ASSERT_FALSE(result);
  EXPECT_EQ(result.error().code, ErrorCode::kCancelled);
}

TEST_F(FaultTest, StalledTransferTimesOutAndIsRetried) {
  HttpOptions options = quickOptions();
  options.stall_timeout = std::chrono::milliseconds(1000);
  auto source = open(options);
  ASSERT_TRUE(source);
  server_.setPlan([](uint64_t n) {
    return n == 1 ? test::RangeReply{test::RangeReply::Kind::kStall} : test::RangeReply{};
  });
  EXPECT_EQ(readRange(*source, 1000, 100000), slice(bytes_, 1000, 100000));
  EXPECT_EQ(source->linkStats()->retries, 1u);
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Servers that do not do multi-range requests: the RangeServer answers only the first range
// of a Range header, or (by plan) the whole file.
class MultiRangeFallbackTest : public FaultTest {
 protected:
  std::vector<ByteRange> threeRanges() { return farApartRanges(outs_, 3, 20000, 80000, 9); }
  void expectBytes(const std::vector<ByteRange>& ranges) {
    for (size_t i = 0; i < outs_.size(); ++i)
      EXPECT_EQ(outs_[i], slice(bytes_, ranges[i].offset_bytes, outs_[i].size())) << i;
  }
  std::vector<std::vector<uint8_t>> outs_;
};

TEST_F(MultiRangeFallbackTest, SingleRangeAnswerFallsBackRangeByRangeAndIsRemembered) {
  auto source = open();
  ASSERT_TRUE(source);
  std::vector<ByteRange> ranges = threeRanges();
  const LinkStats before = *source->linkStats();
  ASSERT_TRUE(source->readMany(ranges));
  expectBytes(ranges);
  const LinkStats after = *source->linkStats();
  // The refused request stopped at its first body bytes: at most the first range's.
  uint64_t asked = 0;
  for (const ByteRange& range : ranges) asked += range.length_bytes;
  EXPECT_LE(after.bytes_received - before.bytes_received, asked + ranges[0].length_bytes);
  EXPECT_EQ(after.errors, 0u);
  std::vector<test::SeenRequest> seen = server_.seen();
  ASSERT_EQ(seen.size(), 5u);  // the open, the multi-range request, then one per range
  EXPECT_NE(seen[1].range.find(','), std::string::npos) << seen[1].range;
  for (size_t i = 2; i < seen.size(); ++i)
    EXPECT_EQ(seen[i].range.find(','), std::string::npos) << seen[i].range;
  // Remembered: the next readMany asks range by range at once.
  ranges = threeRanges();
  ASSERT_TRUE(source->readMany(ranges));
  expectBytes(ranges);
  seen = server_.seen();
  ASSERT_EQ(seen.size(), 8u);
  for (size_t i = 5; i < seen.size(); ++i)
    EXPECT_EQ(seen[i].range.find(','), std::string::npos) << seen[i].range;
}

TEST_F(MultiRangeFallbackTest, WholeFileAnswerIsCutShortAndFallsBack) {
  auto source = open();
  ASSERT_TRUE(source);
  server_.setPlan([](uint64_t n) {
    return n == 1 ? test::RangeReply{test::RangeReply::Kind::kWholeFile} : test::RangeReply{};
  });
  std::vector<ByteRange> ranges = threeRanges();
  const uint64_t before = source->linkStats()->bytes_received;
  ASSERT_TRUE(source->readMany(ranges));
  expectBytes(ranges);
  // libcurl hands the body over in pieces of at most 16 KiB: the first is all it took.
  const uint64_t received = source->linkStats()->bytes_received - before;
  EXPECT_LT(received, bytes_.size() / 4);
  EXPECT_EQ(server_.seen().size(), 5u);
}

TEST_F(MultiRangeFallbackTest, MultipartPartsInAnyOrderGiveEachRangeItsBytes) {
  auto source = open();
  ASSERT_TRUE(source);
  server_.setPlan([](uint64_t) { return test::RangeReply{test::RangeReply::Kind::kMultipart}; });
  std::vector<ByteRange> ranges = threeRanges();
  Result<void> read = source->readMany(ranges);
  ASSERT_TRUE(read) << read.error().message;
  expectBytes(ranges);
  EXPECT_EQ(server_.seen().size(), 2u);  // the open and one multi-range request
}

TEST_F(MultiRangeFallbackTest, MislabelledOrOversizedMultipartFailsNamingTheRequest) {
  for (auto kind : {test::RangeReply::Kind::kMultipartWrongRange,
                    test::RangeReply::Kind::kMultipartOversized}) {
    auto source = open();
    ASSERT_TRUE(source);
    server_.setPlan([kind](uint64_t) { return test::RangeReply{kind}; });
    std::vector<ByteRange> ranges = threeRanges();
    Result<void> read = source->readMany(ranges);
    ASSERT_FALSE(read);
    EXPECT_EQ(read.error().code, ErrorCode::kIo);
    EXPECT_NE(read.error().message.find(server_.url()), std::string::npos);
    EXPECT_NE(read.error().message.find(kind == test::RangeReply::Kind::kMultipartWrongRange
                                            ? "no part holding bytes"
                                            : "server sent more than"),
              std::string::npos)
        << read.error().message;
    server_.setPlan({});
  }
}

TEST_F(MultiRangeFallbackTest, ReadEachSendsOneRequestAndFailsOnlyTheMislabelledRange) {
  auto source = open();
  ASSERT_TRUE(source);
  server_.setPlan([](uint64_t) {
    return test::RangeReply{test::RangeReply::Kind::kMultipartFirstMislabelled};
  });
  std::vector<ByteRange> ranges = threeRanges();
  // Out of file order: each result must still be its own range's.
  std::swap(ranges[0], ranges[2]);
  std::swap(outs_[0], outs_[2]);
  const std::atomic<bool> cancel{false};
  std::vector<Result<void>> results = source->readEach(ranges, cancel);
  ASSERT_EQ(results.size(), 3u);
  // The lowest range, now third, was the server's first: its part is one byte off.
  ASSERT_FALSE(results[2]);
  EXPECT_EQ(results[2].error().code, ErrorCode::kIo);
  EXPECT_NE(results[2].error().message.find("no part holding bytes " +
                                            std::to_string(ranges[2].offset_bytes) + "-"),
            std::string::npos)
      << results[2].error().message;
  for (size_t i = 0; i < 2; ++i) {
    ASSERT_TRUE(results[i]) << results[i].error().message;
    EXPECT_EQ(outs_[i], slice(bytes_, ranges[i].offset_bytes, outs_[i].size())) << i;
  }
  EXPECT_EQ(server_.seen().size(), 2u);  // the open and one multi-range request
  EXPECT_EQ(source->linkStats()->errors, 1u);
}

TEST_F(MultiRangeFallbackTest, ReadEachWithoutMultiRangeReadsEveryRangeAndRemembers) {
  auto source = open();
  ASSERT_TRUE(source);
  EXPECT_TRUE(source->readsRangesTogether());
  const std::atomic<bool> cancel{false};
  for (size_t round = 0; round < 2; ++round) {
    std::vector<ByteRange> ranges = threeRanges();
    std::vector<Result<void>> results = source->readEach(ranges, cancel);
    ASSERT_EQ(results.size(), 3u);
    for (const Result<void>& result : results) ASSERT_TRUE(result) << result.error().message;
    expectBytes(ranges);
  }
  // The open, the refused multi-range request and three singles; then three singles.
  const std::vector<test::SeenRequest> seen = server_.seen();
  ASSERT_EQ(seen.size(), 8u);
  for (size_t i = 2; i < seen.size(); ++i)
    EXPECT_EQ(seen[i].range.find(','), std::string::npos) << seen[i].range;
}

TEST_F(MultiRangeFallbackTest, ReadEachCancelledBeforeItStartsSendsNothing) {
  auto source = open();
  ASSERT_TRUE(source);
  const std::atomic<bool> cancel{true};
  std::vector<ByteRange> ranges = threeRanges();
  for (const Result<void>& result : source->readEach(ranges, cancel)) {
    ASSERT_FALSE(result);
    EXPECT_EQ(result.error().code, ErrorCode::kCancelled);
  }
  EXPECT_EQ(server_.seen().size(), 1u);
}

}  // namespace
}  // namespace tessera
