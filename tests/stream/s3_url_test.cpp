// resolveS3Url: s3:// URLs to the HTTP source's URL and signing options, from the options and
// the environment as the AWS tools take them (docs/remote.md, "Object stores").
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include <tessera/http_source.h>
#include <tessera/open.h>

namespace tessera {
namespace {

/// Clears every AWS_* variable this code reads for the test's life, and restores them after.
class S3Environment : public testing::Test {
 protected:
  void SetUp() override {
    for (const char* name : kNames) {
      const char* value = std::getenv(name);
      saved_.emplace_back(name, value ? std::optional<std::string>(value) : std::nullopt);
      ::unsetenv(name);
    }
    ::setenv("HOME", "/nonexistent-home", 1);
  }
  void TearDown() override {
    for (const auto& [name, value] : saved_) {
      if (value)
        ::setenv(name.c_str(), value->c_str(), 1);
      else
        ::unsetenv(name.c_str());
    }
  }
  static constexpr const char* kNames[] = {"AWS_ENDPOINT_URL",
                                           "AWS_ENDPOINT_URL_S3",
                                           "AWS_REGION",
                                           "AWS_DEFAULT_REGION",
                                           "AWS_ACCESS_KEY_ID",
                                           "AWS_SECRET_ACCESS_KEY",
                                           "AWS_SESSION_TOKEN",
                                           "AWS_SHARED_CREDENTIALS_FILE",
                                           "AWS_CONFIG_FILE",
                                           "AWS_PROFILE",
                                           "HOME"};
  std::vector<std::pair<std::string, std::optional<std::string>>> saved_;
};

TEST_F(S3Environment, AwsItselfIsVirtualHostedAndUnsignedWithoutCredentials) {
  auto target = resolveS3Url("s3://my-bucket/maps/earth 2.tess");
  ASSERT_TRUE(target) << target.error().message;
  EXPECT_EQ(target->url, "https://my-bucket.s3.us-east-1.amazonaws.com/maps/earth%202.tess");
  EXPECT_TRUE(target->options.aws.access_key_id.empty());
}

TEST_F(S3Environment, EndpointFromTheEnvironmentIsPathStyleAndTheS3OneWins) {
  ::setenv("AWS_ENDPOINT_URL", "http://general:1", 1);
  ::setenv("AWS_ENDPOINT_URL_S3", "http://127.0.0.1:9000/", 1);
  ::setenv("AWS_DEFAULT_REGION", "eu-north-1", 1);
  ::setenv("AWS_ACCESS_KEY_ID", "AKID", 1);
  ::setenv("AWS_SECRET_ACCESS_KEY", "secret", 1);
  ::setenv("AWS_SESSION_TOKEN", "token", 1);
  auto target = resolveS3Url("s3://tiles/a/b.tess");
  ASSERT_TRUE(target) << target.error().message;
  EXPECT_EQ(target->url, "http://127.0.0.1:9000/tiles/a/b.tess");
  EXPECT_EQ(target->options.aws.region, "eu-north-1");
  EXPECT_EQ(target->options.aws.access_key_id, "AKID");
  EXPECT_EQ(target->options.aws.session_token, "token");

  S3Options options;
  options.endpoint = "https://minio.example:443";
  options.region = "ap-east-1";
  target = resolveS3Url("s3://tiles/a/b.tess", options);
  ASSERT_TRUE(target);
  EXPECT_EQ(target->url, "https://minio.example:443/tiles/a/b.tess");
  EXPECT_EQ(target->options.aws.region, "ap-east-1");
}

TEST_F(S3Environment, ProfilesComeFromTheCredentialsAndConfigFiles) {
  const auto dir = std::filesystem::temp_directory_path() / "tessera-s3-profile-test";
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "credentials")
      << "[default]\naws_access_key_id = D\naws_secret_access_key = d\n"
         "[work]\n aws_access_key_id=W \naws_secret_access_key = w\n";
  std::ofstream(dir / "config")
      << "[default]\nregion = us-west-2\n[profile work]\nregion = sa-east-1\n";
  ::setenv("AWS_SHARED_CREDENTIALS_FILE", (dir / "credentials").c_str(), 1);
  ::setenv("AWS_CONFIG_FILE", (dir / "config").c_str(), 1);
  auto target = resolveS3Url("s3://tiles/x.tess");
  ASSERT_TRUE(target) << target.error().message;
  EXPECT_EQ(target->options.aws.access_key_id, "D");
  EXPECT_EQ(target->options.aws.region, "us-west-2");
  ::setenv("AWS_PROFILE", "work", 1);
  target = resolveS3Url("s3://tiles/x.tess");
  ASSERT_TRUE(target);
  EXPECT_EQ(target->options.aws.access_key_id, "W");
  EXPECT_EQ(target->options.aws.secret_access_key, "w");
  EXPECT_EQ(target->options.aws.region, "sa-east-1");
  std::filesystem::remove_all(dir);
}

TEST_F(S3Environment, BadUrlsAndHalfCredentialsAreRefusedNamingThem) {
  for (const char* url : {"s3://", "s3://bucket", "s3://bucket/", "s3:///key", "s3://B_d/key",
                          "s3://ab/key", "s3://user@host/key"}) {
    auto target = resolveS3Url(url);
    ASSERT_FALSE(target) << url;
    EXPECT_NE(target.error().message.find(url), std::string::npos) << target.error().message;
  }
  ::setenv("AWS_ENDPOINT_URL", "ftp://host", 1);
  EXPECT_FALSE(resolveS3Url("s3://tiles/k"));
  ::setenv("AWS_ENDPOINT_URL", "http://host/path", 1);
  EXPECT_FALSE(resolveS3Url("s3://tiles/k"));
  ::unsetenv("AWS_ENDPOINT_URL");
  ::setenv("AWS_ACCESS_KEY_ID", "only-the-id", 1);
  auto half = resolveS3Url("s3://tiles/k");
  ASSERT_FALSE(half);
  EXPECT_NE(half.error().message.find("AWS_SECRET_ACCESS_KEY"), std::string::npos);
  EXPECT_TRUE(isRemoteUri("s3://tiles/k"));
  EXPECT_FALSE(openHttpSource("s3://tiles/k"));
}

}  // namespace
}  // namespace tessera
