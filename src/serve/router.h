#pragma once
// Request -> response for every endpoint of docs/serve.md. Synchronous and socket-free, so
// the connection code stays about I/O and tests can call it directly.

#include <chrono>
#include <functional>
#include <map>
#include <memory>
#include <string>

#include <boost/beast/http/message.hpp>
#include <boost/beast/http/string_body.hpp>

#include <tessera/serve.h>

#include "catalog.h"
#include "metrics.h"
#include "parts_body.h"
#include "transcode_cache.h"

namespace tessera::detail {

using Request = boost::beast::http::request<boost::beast::http::string_body>;
using Response = boost::beast::http::response<PartsBody>;

struct RoutedResponse {
  Endpoint endpoint = Endpoint::kOther;
  Response response;
};

/// Thread-safe: the catalog and JSON documents are immutable, the cache and metrics
/// synchronise themselves.
class Router {
 public:
  Router(Catalog catalog, const ServeOptions& options, Metrics& metrics);

  /// Answers `request`. Never throws; archive failures become 500 with the error's message.
  RoutedResponse handle(const Request& request);

  /// A plain-text error response (also used by the connection for malformed requests).
  Response errorResponse(unsigned version, boost::beast::http::status status,
                         std::string_view reason) const;

  const Catalog& catalog() const { return catalog_; }
  TranscodeCache& cache() { return cache_; }

  /// A request target split into decoded path segments (see router.cpp, parseTarget).
  struct Target;

 private:
  RoutedResponse route(const Request& request, const Target& target);
  Response archiveFile(const Request& request, const ServedArchive& served);
  /// 503 for an archive whose file was modified in place after start (ServedArchive).
  Response changedOnDisk(unsigned version, const ServedArchive& served) const;
  Response tile(const Request& request, const ServedArchive& served, const Target& target);
  Response dziDescriptor(const Request& request, const ServedArchive& served, uint32_t image);
  Response picture(const Request& request, const ServedArchive& served, const std::string& key,
                   const std::function<Result<std::string>()>& render, const char* content_type);
  Response viewerFile(const Request& request, std::string_view path);
  Response bytesResponse(const Request& request, std::shared_ptr<const std::string> body,
                         std::string_view content_type, std::string_view etag,
                         std::string_view cache_control);
  Response bytesResponse(const Request& request, BodyPart body, std::string_view content_type,
                         std::string_view etag, std::string_view cache_control);
  void addCommonHeaders(Response& response) const;

  const Catalog catalog_;
  const ServeOptions options_;
  Metrics& metrics_;
  TranscodeCache cache_;
  std::shared_ptr<const std::string> archives_json_;
  std::map<std::string, std::shared_ptr<const std::string>> info_json_;  // by archive name
};

}  // namespace tessera::detail
