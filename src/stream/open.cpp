#include <tessera/open.h>

#include <cstdlib>
#include <string_view>

#include <tessera/http_source.h>

namespace tessera {

bool isRemoteUri(const std::string& path_or_url) {
  std::string head = path_or_url.substr(0, 8);
  for (char& c : head) c = char(c >= 'A' && c <= 'Z' ? c - 'A' + 'a' : c);
  return head.rfind("http://", 0) == 0 || head.rfind("https://", 0) == 0 ||
         head.rfind("s3://", 0) == 0;
}

namespace {

/// The HTTP client's settings the tools take from the environment, never from the command
/// line, which every user of the machine can read in the process list.
HttpOptions httpOptionsFromEnvironment() {
  HttpOptions options;
  if (const char* token = std::getenv("TESSERA_TOKEN"); token && *token)
    options.bearer_token = token;
  if (const char* ca_file = std::getenv("TESSERA_CA_FILE"); ca_file && *ca_file)
    options.ca_file = ca_file;
  // Spelled out in full so that it is never set by accident.
  if (const char* insecure = std::getenv("TESSERA_TLS_INSECURE");
      insecure && std::string_view(insecure) == "1")
    options.verify_tls = false;
  if (const char* http2 = std::getenv("TESSERA_HTTP2"); http2 && std::string_view(http2) == "0")
    options.http2 = false;
  return options;
}

}  // namespace

Result<std::shared_ptr<ByteSource>> openByteSource(const std::string& path_or_url) {
  if (path_or_url.rfind("s3://", 0) == 0) {
    S3Options options;
    options.http = httpOptionsFromEnvironment();
    options.http.bearer_token.clear();  // an object store authenticates by signature
    return openS3Source(path_or_url, options);
  }
  if (isRemoteUri(path_or_url)) return openHttpSource(path_or_url, httpOptionsFromEnvironment());
  return openFileSource(path_or_url);
}

Result<std::shared_ptr<Archive>> openArchive(const std::string& path_or_url) {
  TESSERA_ASSIGN_OR_RETURN(std::shared_ptr<ByteSource> source, openByteSource(path_or_url));
  return Archive::open(std::move(source));
}

}  // namespace tessera
