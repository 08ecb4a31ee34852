// Access control of `tessera serve`: the rules on their own (globs, the access file's checks,
// bearer tokens, signed URLs for a path, an archive or a byte range, rate limits), then a
// running server that must not give a protected archive's bytes, or even its existence, to
// a request without the right credential on any route.
#include "access.h"

#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <tessera/archive.h>

#include "serve/serve_fixture.h"

namespace tessera::detail {
namespace {

using namespace std::chrono_literals;

constexpr std::string_view kToken = "token-for-the-scans-0123456789";
constexpr std::string_view kSecret = "a-signing-secret-of-at-least-32-bytes-long";

std::string rulesJson() {
  return nlohmann::json{
      {"public", {"pngb1", "open-*"}},
      {"tokens", {{{"token", kToken}, {"archives", {"zstd4", "scan-?"}}}}},
      {"signing_keys", {{{"id", "web"}, {"secret", kSecret}, {"archives", {"jpeg3"}}}}},
      {"cors",
       {{{"archives", {"zstd4"}}, {"origin", "https://maps.example.org"}},
        {{"archives", {"*"}}, {"origin", "*"}}}},
  }
      .dump();
}

std::shared_ptr<const AccessRules> rules(const std::string& json = rulesJson()) {
  Result<std::shared_ptr<const AccessRules>> parsed = AccessRules::parse(json, "access.json");
  EXPECT_TRUE(parsed) << parsed.error().message;
  return parsed ? *parsed : nullptr;
}

AccessVerdict verdictOf(const AccessRules& access, std::string_view archive, std::string_view path,
                        std::string_view query = {}, std::string_view authorization = {},
                        std::string_view range = {}, int64_t now = 1'000'000) {
  return access.authorize({archive, path, query, authorization, range, now}).verdict;
}

TEST(Access, GlobsMatchWholeNames) {
  EXPECT_TRUE(archiveMatches("earth", "earth"));
  EXPECT_FALSE(archiveMatches("earth", "earth2"));
  EXPECT_TRUE(archiveMatches("scan-*", "scan-0012"));
  EXPECT_TRUE(archiveMatches("*", ""));
  EXPECT_TRUE(archiveMatches("s?an-*-x", "scan-a-b-x"));
  EXPECT_FALSE(archiveMatches("s?an-*-x", "scan-a-b-y"));
  EXPECT_TRUE(archiveMatches("*a*a*a*", "banana-a"));
  // A long near-miss takes linear time, not exponential.
  EXPECT_FALSE(archiveMatches("*a*a*a*a*a*a*a*a*b", std::string(4000, 'a')));
}

TEST(Access, TheFileIsCheckedEntryByEntry) {
  const auto error = [](const std::string& json) {
    Result<std::shared_ptr<const AccessRules>> parsed = AccessRules::parse(json, "access.json");
    return parsed ? std::string() : parsed.error().message;
  };
  EXPECT_NE(error(R"({"tokens": [{"token": "short", "archives": ["a"]}]})")
                .find("access.json: tokens[0]: \"token\" has 5 bytes"),
            std::string::npos);
  EXPECT_EQ(error(R"({"tokens": [{"token": "short", "archives": ["a"]}]})").find("short\""),
            std::string::npos)
      << "a message never holds a secret";
  EXPECT_NE(error(R"({"signing_keys": [{"id": "k", "secret": "0123456789", "archives": ["a"]}]})")
                .find("signing_keys[0]: \"secret\" has 10 bytes"),
            std::string::npos);
  EXPECT_NE(error(R"({"publik": ["a"]})").find("unknown key \"publik\""), std::string::npos);
  EXPECT_NE(error(R"({"public": []})").find("non-empty list"), std::string::npos);
  EXPECT_NE(error(R"({"rate_limit": {"requests_per_second": 0}})").find("rate_limit"),
            std::string::npos);
  EXPECT_NE(error("[1]").find("not a JSON object"), std::string::npos);
  EXPECT_NE(error(R"({"signing_keys": [{"id": "a&b", "secret": "0123456789012345678901234567890123",
                      "archives": ["a"]}]})")
                .find("\"id\""),
            std::string::npos);
  EXPECT_EQ(error(rulesJson()), "");
}

TEST(Access, BearerTokensReachTheirArchivesOnly) {
  auto access = rules();
  const std::string bearer = "Bearer " + std::string(kToken);
  EXPECT_EQ(verdictOf(*access, "pngb1", "/pngb1.tess"), AccessVerdict::kAllowed);
  EXPECT_EQ(verdictOf(*access, "open-data", "/open-data/info.json"), AccessVerdict::kAllowed);
  EXPECT_EQ(verdictOf(*access, "zstd4", "/zstd4.tess"), AccessVerdict::kUnauthenticated);
  EXPECT_EQ(verdictOf(*access, "zstd4", "/zstd4.tess", "", bearer), AccessVerdict::kAllowed);
  EXPECT_EQ(verdictOf(*access, "scan-7", "/scan-7/info.json", "", "bearer " + std::string(kToken)),
            AccessVerdict::kAllowed);
  EXPECT_EQ(verdictOf(*access, "jpeg3", "/jpeg3.tess", "", bearer), AccessVerdict::kForbidden);
  EXPECT_EQ(verdictOf(*access, "zstd4", "/zstd4.tess", "", bearer + "x"),
            AccessVerdict::kUnauthenticated);
  EXPECT_EQ(verdictOf(*access, "zstd4", "/zstd4.tess", "", "Basic dXNlcjpwYXNz"),
            AccessVerdict::kUnauthenticated);
  // Whether the archive exists is not the rules' business: the same answer either way.
  EXPECT_EQ(verdictOf(*access, "nope", "/nope.tess"), AccessVerdict::kUnauthenticated);
  EXPECT_TRUE(access->mayList("zstd4", bearer));
  EXPECT_FALSE(access->mayList("zstd4", ""));
  EXPECT_TRUE(access->mayList("pngb1", ""));
}

TEST(Access, SignedUrlsHoldForTheirPathArchiveRangeAndTimeOnly) {
  auto access = rules();
  const int64_t now = 1'000'000, later = now + 600;
  const std::string path_sig = signedQuery("web", kSecret, "/jpeg3.tess", later, "");
  EXPECT_EQ(verdictOf(*access, "jpeg3", "/jpeg3.tess", path_sig, "", "bytes=0-99", now),
            AccessVerdict::kAllowed);
  EXPECT_EQ(verdictOf(*access, "jpeg3", "/jpeg3/info.json", path_sig, "", "", now),
            AccessVerdict::kForbidden)
      << "a signature for another path";
  EXPECT_EQ(verdictOf(*access, "jpeg3", "/jpeg3.tess", path_sig, "", "", later + 1),
            AccessVerdict::kForbidden)
      << "expired";
  std::string tampered = path_sig;
  tampered.back() = tampered.back() == '0' ? '1' : '0';
  EXPECT_EQ(verdictOf(*access, "jpeg3", "/jpeg3.tess", tampered, "", "", now),
            AccessVerdict::kForbidden);
  EXPECT_EQ(verdictOf(*access, "jpeg3", "/jpeg3.tess", path_sig + "&sig=00", "", "", now),
            AccessVerdict::kForbidden)
      << "a parameter given twice";
  const std::string later_forged =
      std::string(path_sig).replace(path_sig.find(std::to_string(later)),
                                    std::to_string(later).size(), std::to_string(later + 86400));
  EXPECT_EQ(verdictOf(*access, "jpeg3", "/jpeg3.tess", later_forged, "", "", later + 10),
            AccessVerdict::kForbidden)
      << "an expiry moved by hand";

  const std::string archive_sig = signedQuery("web", kSecret, "archive:jpeg3", later, "");
  EXPECT_EQ(verdictOf(*access, "jpeg3", "/jpeg3/0_files/0/0_0.jpg", archive_sig, "", "", now),
            AccessVerdict::kAllowed);
  EXPECT_EQ(verdictOf(*access, "zstd4", "/zstd4/info.json", archive_sig, "", "", now),
            AccessVerdict::kForbidden)
      << "signed for another archive";

  const std::string range_sig = signedQuery("web", kSecret, "/jpeg3.tess", later, "100-199");
  EXPECT_EQ(verdictOf(*access, "jpeg3", "/jpeg3.tess", range_sig, "", "bytes=100-149,150-199", now),
            AccessVerdict::kAllowed);
  EXPECT_EQ(verdictOf(*access, "jpeg3", "/jpeg3.tess", range_sig, "", "bytes=100-200", now),
            AccessVerdict::kForbidden);
  EXPECT_EQ(verdictOf(*access, "jpeg3", "/jpeg3.tess", range_sig, "", "bytes=100-", now),
            AccessVerdict::kForbidden);
  EXPECT_EQ(verdictOf(*access, "jpeg3", "/jpeg3.tess", range_sig, "", "", now),
            AccessVerdict::kForbidden)
      << "no Range field: the whole file is outside the signed range";

  // A key only reaches its archives, and a key nobody configured signs nothing.
  const std::string wrong_archive = signedQuery("web", kSecret, "/zstd4.tess", later, "");
  EXPECT_EQ(verdictOf(*access, "zstd4", "/zstd4.tess", wrong_archive, "", "", now),
            AccessVerdict::kForbidden);
  const std::string unknown_key = signedQuery("other", kSecret, "/jpeg3.tess", later, "");
  EXPECT_EQ(verdictOf(*access, "jpeg3", "/jpeg3.tess", unknown_key, "", "", now),
            AccessVerdict::kForbidden);
}

TEST(Access, RateLimiterRefillsAtItsRateAndSaysWhenToComeBack) {
  RateLimiter limiter(2.0, 3.0);
  const auto t0 = std::chrono::steady_clock::time_point(100s);
  for (int i = 0; i < 3; ++i) EXPECT_TRUE(limiter.admit("10.0.0.1", t0)) << i;
  double retry = 0;
  EXPECT_FALSE(limiter.admit("10.0.0.1", t0, &retry));
  EXPECT_NEAR(retry, 0.5, 1e-9);
  EXPECT_TRUE(limiter.admit("10.0.0.2", t0)) << "each address has its own bucket";
  EXPECT_TRUE(limiter.admit("10.0.0.1", t0 + 500ms));
  EXPECT_FALSE(limiter.admit("10.0.0.1", t0 + 500ms));
  RateLimiter unlimited(0, 0);
  for (int i = 0; i < 1000; ++i) ASSERT_TRUE(unlimited.admit("x", t0));
  // Memory stays bounded however many addresses come.
  RateLimiter small(1.0, 1.0, 8);
  for (int i = 0; i < 100; ++i) small.admit(std::to_string(i), t0 + std::chrono::seconds(i));
  EXPECT_TRUE(small.admit("99", t0 + 200s));
}

class AccessServerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    paths_ = {test::servedArchive("pngb1", 1000, 700, 3, Codec::kPng, 128, 1),
              test::servedArchive("zstd4", 600, 400, 4, Codec::kZstd, 64, 0),
              test::servedArchive("jpeg3", 700, 500, 3, Codec::kJpeg, 256, 0)};
    // One folder per test and process: ctest runs these tests in parallel processes.
    dir_ = std::filesystem::path(::testing::TempDir()) /
           ("tessera-access-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
    access_file_ = (dir_ / "access.json").string();
    std::ofstream(access_file_) << rulesJson();
  }
  void TearDown() override {
    std::error_code ignored;
    std::filesystem::remove_all(dir_, ignored);
  }
  std::unique_ptr<TileServer> start(ServeOptions options = {}) {
    options.access_file = access_file_;
    return test::startServer(paths_, options);
  }
  std::vector<std::string> paths_;
  std::filesystem::path dir_;
  std::string access_file_;
};

// Every route of a protected archive, and of one that does not exist, answers 401 with the
// same body, naming nothing.
TEST_F(AccessServerTest, NoRouteOfAProtectedArchiveAnswersWithoutACredential) {
  auto server = start();
  ASSERT_NE(server, nullptr);
  const uint16_t port = server->port();
  std::string body_of_missing;
  for (const std::string name : {"zstd4", "nope"}) {
    for (const std::string& target :
         {"/" + name + ".tess", "/" + name + "/info.json", "/" + name + "/0.dzi",
          "/" + name + "/0_files/0/0_0.png", "/" + name + "/0/xyz/0/0/0.png",
          "/" + name + "/0/0/0/0", "/" + name + "/0/0/0/0?format=png",
          // The display window's parameters: checked after the credential, never before.
          "/" + name + "/0/0/0/0?format=png&window=0,100&gamma=2",
          "/" + name + "/0/0/0/0?format=png&window=bad"}) {
      for (const char* method : {"GET", "HEAD"}) {
        test::HttpReply reply = test::httpRequest(port, target, {}, method);
        EXPECT_EQ(reply.status, 401u) << method << " " << target;
        EXPECT_EQ(reply.header("www-authenticate"), R"(Bearer realm="tessera")") << target;
        EXPECT_EQ(reply.body.find(name), std::string::npos) << target;
        EXPECT_EQ(reply.header("etag"), "") << target;
        if (name == "nope" && std::string(method) == "GET") body_of_missing = reply.body;
      }
    }
  }
  EXPECT_EQ(test::httpRequest(port, "/zstd4.tess").body, body_of_missing);
  // A wrong token is 401 too, marked invalid; a right token for another archive is 403.
  test::HttpReply wrong = test::httpRequest(port, "/zstd4.tess", {{"Authorization", "Bearer no"}});
  EXPECT_EQ(wrong.status, 401u);
  EXPECT_NE(wrong.header("www-authenticate").find("invalid_token"), std::string::npos);
  const std::string bearer = "Bearer " + std::string(kToken);
  EXPECT_EQ(test::httpRequest(port, "/jpeg3.tess", {{"Authorization", bearer}}).status, 403u);
}

TEST_F(AccessServerTest, CredentialsOpenTheirArchivesPrivatelyAndTheListFollowsThem) {
  auto server = start();
  ASSERT_NE(server, nullptr);
  const uint16_t port = server->port();
  const std::string bearer = "Bearer " + std::string(kToken);
  test::HttpReply tile = test::httpRequest(port, "/zstd4/0/0/0/0", {{"Authorization", bearer}});
  EXPECT_EQ(tile.status, 200u);
  EXPECT_TRUE(tile.header("cache-control").starts_with("private")) << tile.header("cache-control");
  EXPECT_EQ(tile.header("access-control-allow-origin"), "https://maps.example.org");
  test::HttpReply open = test::httpRequest(port, "/pngb1/0/0/0/0");
  EXPECT_EQ(open.status, 200u);
  EXPECT_TRUE(open.header("cache-control").starts_with("public"));
  EXPECT_EQ(open.header("access-control-allow-origin"), "*");

  const auto names = [&](const std::map<std::string, std::string>& headers) {
    std::vector<std::string> out;
    test::HttpReply list = test::httpRequest(port, "/api/archives", headers);
    EXPECT_EQ(list.header("cache-control"), "private, no-store");
    const nlohmann::json doc = nlohmann::json::parse(list.body);
    for (const auto& entry : doc["archives"]) out.push_back(entry["name"]);
    return out;
  };
  EXPECT_EQ(names({}), std::vector<std::string>({"pngb1"}));
  EXPECT_EQ(names({{"Authorization", bearer}}), std::vector<std::string>({"pngb1", "zstd4"}));

  // A signed URL for a byte range of the archive file: that range only, until it expires.
  const int64_t now = std::chrono::duration_cast<std::chrono::seconds>(
                          std::chrono::system_clock::now().time_since_epoch())
                          .count();
  const std::string query = signedQuery("web", kSecret, "/jpeg3.tess", now + 300, "0-16383");
  test::HttpReply ranged =
      test::httpRequest(port, "/jpeg3.tess?" + query, {{"Range", "bytes=0-1023"}});
  EXPECT_EQ(ranged.status, 206u);
  EXPECT_EQ(ranged.body.size(), 1024u);
  EXPECT_EQ(
      test::httpRequest(port, "/jpeg3.tess?" + query, {{"Range", "bytes=16384-16400"}}).status,
      403u);
  const std::string expired = signedQuery("web", kSecret, "/jpeg3.tess", now - 1, "0-16383");
  EXPECT_EQ(test::httpRequest(port, "/jpeg3.tess?" + expired, {{"Range", "bytes=0-9"}}).status,
            403u);
}

// The stored blocks of a bc1 archive, which the web viewer uploads as they are, are a tile
// route like the others: no bytes without the token, the stored payload with it.
TEST_F(AccessServerTest, BlockTilesOfAProtectedArchiveNeedTheToken) {
  paths_.push_back(test::servedArchive("scan-b", 200, 150, 3, Codec::kBc1, 64, 0));
  auto server = start();
  ASSERT_NE(server, nullptr);
  const uint16_t port = server->port();
  std::shared_ptr<Archive> archive = Archive::openFile(paths_.back()).value();
  const TileId id{0, 0, 0, 0};
  const TileEntry entry = archive->tileEntry(id).value();
  ASSERT_EQ(entry.kind, TileKind::kEncoded);
  const std::vector<uint8_t> payload = archive->readPayload(id, entry).value();
  for (const char* method : {"GET", "HEAD"}) {
    test::HttpReply refused = test::httpRequest(port, "/scan-b/0/0/0/0", {}, method);
    EXPECT_EQ(refused.status, 401u) << method;
    EXPECT_EQ(refused.header("etag"), "") << method;
    EXPECT_EQ(refused.body.find(std::string(payload.begin(), payload.begin() + 8)),
              std::string::npos);
  }
  const std::string bearer = "Bearer " + std::string(kToken);
  test::HttpReply tile = test::httpRequest(port, "/scan-b/0/0/0/0", {{"Authorization", bearer}});
  ASSERT_EQ(tile.status, 200u) << tile.body;
  EXPECT_EQ(tile.body, std::string(payload.begin(), payload.end()));
  EXPECT_EQ(tile.header("x-tessera-codec"), "bc1");
  EXPECT_TRUE(tile.header("cache-control").starts_with("private")) << tile.header("cache-control");
  test::HttpReply head =
      test::httpRequest(port, "/scan-b/0/0/0/0", {{"Authorization", bearer}}, "HEAD");
  EXPECT_EQ(head.status, 200u);
  EXPECT_EQ(head.header("content-length"), std::to_string(payload.size()));
}

TEST_F(AccessServerTest, RateLimitsAnswer429AndTheLogHidesSignatures) {
  nlohmann::json limited = nlohmann::json::parse(rulesJson());
  limited["rate_limit"] = {{"requests_per_second", 0.001}, {"burst", 3}};
  std::ofstream(access_file_) << limited.dump();
  ServeOptions options;
  options.access_log = (dir_ / "access.log").string();
  std::filesystem::remove(options.access_log);
  auto server = start(options);
  ASSERT_NE(server, nullptr);
  const uint16_t port = server->port();
  const std::string query = signedQuery("web", kSecret, "/jpeg3/info.json", 4'000'000'000, "");
  EXPECT_EQ(test::httpRequest(port, "/jpeg3/info.json?" + query).status, 200u);
  EXPECT_EQ(test::httpRequest(port, "/healthz").status, 200u);
  EXPECT_EQ(test::httpRequest(port, "/pngb1/info.json").status, 200u);
  test::HttpReply refused = test::httpRequest(port, "/pngb1/info.json");
  EXPECT_EQ(refused.status, 429u);
  EXPECT_GE(std::stoi(refused.header("retry-after")), 1);
  server.reset();
  std::ifstream in(options.access_log);
  std::stringstream log;
  log << in.rdbuf();
  EXPECT_NE(log.str().find("sig=REDACTED"), std::string::npos) << log.str();
  EXPECT_EQ(log.str().find(query.substr(query.find("sig=") + 4)), std::string::npos);
}

TEST_F(AccessServerTest, AnAccessFileThatDoesNotParseStopsTheStart) {
  std::ofstream(access_file_) << R"({"tokens": [{"token": "short", "archives": ["a"]}]})";
  ServeOptions options;
  options.paths = paths_;
  options.port = 0;
  options.access_file = access_file_;
  Result<std::unique_ptr<TileServer>> started = TileServer::start(options);
  ASSERT_FALSE(started);
  EXPECT_NE(started.error().message.find(access_file_ + ": tokens[0]"), std::string::npos)
      << started.error().message;
}

}  // namespace
}  // namespace tessera::detail
