// s3:// URLs: the endpoint, region and credentials resolved as the AWS command-line tools do,
// then an ordinary HTTP source whose requests libcurl signs (Signature Version 4).

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>

#include <fmt/format.h>

#include <tessera/http_source.h>

namespace tessera {
namespace {

std::string environment(const char* name) {
  const char* value = std::getenv(name);
  return value ? std::string(value) : std::string();
}

std::string trim(const std::string& text) {
  const size_t first = text.find_first_not_of(" \t\r");
  if (first == std::string::npos) return {};
  return text.substr(first, text.find_last_not_of(" \t\r") - first + 1);
}

/// One section of an AWS INI file (credentials or config): key = value lines under
/// "[name]" (the config file writes "[profile name]" for all but the default). A missing file
/// is an empty section; an unreadable one an error naming it.
Result<std::map<std::string, std::string>> readProfile(const std::string& file,
                                                       const std::string& section) {
  std::map<std::string, std::string> values;
  std::error_code ignored;
  if (!std::filesystem::exists(file, ignored)) return values;
  std::ifstream in(file);
  if (!in) return fail(ErrorCode::kIo, fmt::format("{}: cannot read the AWS profile file", file));
  bool inside = false;
  std::string line;
  while (std::getline(in, line)) {
    line = trim(line);
    if (line.empty() || line[0] == '#' || line[0] == ';') continue;
    if (line.front() == '[' && line.back() == ']') {
      inside = trim(line.substr(1, line.size() - 2)) == section;
      continue;
    }
    const size_t equals = line.find('=');
    if (inside && equals != std::string::npos)
      values[trim(line.substr(0, equals))] = trim(line.substr(equals + 1));
  }
  return values;
}

std::string homeFile(const std::string& relative) {
  const std::string home = environment("HOME");
  return home.empty() ? std::string() : home + "/" + relative;
}

/// Percent-encodes an object key for the URL path (SigV4's canonical URI): everything but
/// unreserved characters and the '/' separators.
std::string encodeKey(const std::string& key) {
  std::string encoded;
  for (unsigned char c : key) {
    if ((c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-' ||
        c == '_' || c == '.' || c == '~' || c == '/') {
      encoded += char(c);
    } else {
      encoded += fmt::format("%{:02X}", c);
    }
  }
  return encoded;
}

struct BucketAndKey {
  std::string bucket;
  std::string key;
};

Result<BucketAndKey> splitS3Url(const std::string& url) {
  const std::string scheme = "s3://";
  if (url.size() <= scheme.size() || url.compare(0, scheme.size(), scheme) != 0)
    return fail(ErrorCode::kInvalidArgument, fmt::format("{}: not an s3://BUCKET/KEY URL", url));
  const std::string rest = url.substr(scheme.size());
  const size_t slash = rest.find('/');
  if (slash == 0 || slash == std::string::npos || slash + 1 == rest.size())
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: an s3:// URL needs a bucket and a key (s3://BUCKET/KEY)", url));
  BucketAndKey parts{rest.substr(0, slash), rest.substr(slash + 1)};
  // Bucket names are DNS labels (3-63 of a-z 0-9 . -): anything else cannot be addressed,
  // and a '@' or ':' would change the meaning of the URL built from it.
  const bool bucket_ok =
      parts.bucket.size() >= 3 && parts.bucket.size() <= 63 &&
      parts.bucket.find_first_not_of("abcdefghijklmnopqrstuvwxyz0123456789.-") == std::string::npos;
  if (!bucket_ok)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: '{}' is not a valid bucket name (3-63 characters of a-z, 0-9, "
                            "'.' and '-')",
                            url, parts.bucket));
  return parts;
}

std::string resolveRegion(const S3Options& options, const std::string& profile) {
  if (!options.region.empty()) return options.region;
  for (const char* name : {"AWS_REGION", "AWS_DEFAULT_REGION"})
    if (std::string value = environment(name); !value.empty()) return value;
  std::string config = environment("AWS_CONFIG_FILE");
  if (config.empty()) config = homeFile(".aws/config");
  if (!config.empty()) {
    const std::string section = profile == "default" ? profile : "profile " + profile;
    auto values = readProfile(config, section);
    if (values && values->count("region")) return values->at("region");
  }
  return "us-east-1";
}

Result<void> resolveCredentials(const std::string& profile, HttpOptions::AwsSigning& aws) {
  aws.access_key_id = environment("AWS_ACCESS_KEY_ID");
  aws.secret_access_key = environment("AWS_SECRET_ACCESS_KEY");
  aws.session_token = environment("AWS_SESSION_TOKEN");
  if (!aws.access_key_id.empty() || !aws.secret_access_key.empty()) {
    if (aws.access_key_id.empty() || aws.secret_access_key.empty())
      return fail(ErrorCode::kInvalidArgument,
                  "AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY must be set together");
    return {};
  }
  std::string file = environment("AWS_SHARED_CREDENTIALS_FILE");
  if (file.empty()) file = homeFile(".aws/credentials");
  if (file.empty()) return {};
  TESSERA_ASSIGN_OR_RETURN(auto values, readProfile(file, profile));
  aws.access_key_id = values["aws_access_key_id"];
  aws.secret_access_key = values["aws_secret_access_key"];
  aws.session_token = values["aws_session_token"];
  if (aws.access_key_id.empty() != aws.secret_access_key.empty())
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: profile [{}] has only one of aws_access_key_id and "
                            "aws_secret_access_key",
                            file, profile));
  return {};
}

}  // namespace

Result<S3Target> resolveS3Url(const std::string& s3_url, const S3Options& options) {
  TESSERA_ASSIGN_OR_RETURN(BucketAndKey parts, splitS3Url(s3_url));
  std::string profile = environment("AWS_PROFILE");
  if (profile.empty()) profile = "default";

  S3Target target;
  target.options = options.http;
  // S3 answers a request of several ranges with the whole object: ask one range a request.
  target.options.max_ranges_per_request = 1;
  HttpOptions::AwsSigning& aws = target.options.aws;
  aws = {};
  aws.region = resolveRegion(options, profile);
  TESSERA_TRY(resolveCredentials(profile, aws));

  std::string endpoint = options.endpoint;
  for (const char* name : {"AWS_ENDPOINT_URL_S3", "AWS_ENDPOINT_URL"})
    if (endpoint.empty()) endpoint = environment(name);
  if (endpoint.empty()) {
    target.url = fmt::format("https://{}.s3.{}.amazonaws.com/{}", parts.bucket, aws.region,
                             encodeKey(parts.key));
    return target;
  }
  while (!endpoint.empty() && endpoint.back() == '/') endpoint.pop_back();
  const bool http_scheme = endpoint.rfind("http://", 0) == 0 || endpoint.rfind("https://", 0) == 0;
  if (!http_scheme || endpoint.find('/', endpoint.find("//") + 2) != std::string::npos)
    return fail(
        ErrorCode::kInvalidArgument,
        fmt::format("{}: the S3 endpoint '{}' must be http(s)://HOST[:PORT]", s3_url, endpoint));
  target.url = fmt::format("{}/{}/{}", endpoint, parts.bucket, encodeKey(parts.key));
  return target;
}

Result<std::shared_ptr<ByteSource>> openS3Source(const std::string& s3_url,
                                                 const S3Options& options) {
  TESSERA_ASSIGN_OR_RETURN(S3Target target, resolveS3Url(s3_url, options));
  auto source = openHttpSource(target.url, target.options);
  if (!source)
    return fail(source.error().code, fmt::format("{}: {}", s3_url, source.error().message));
  return source;
}

}  // namespace tessera
