#pragma once
// Request -> response for every endpoint of docs/serve.md. Synchronous and socket-free, so
// the connection code stays about I/O and tests can call it directly.

#include <chrono>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string_view>
#include <vector>
#include <string>

#include <boost/beast/http/message.hpp>
#include <boost/beast/http/string_body.hpp>

#include <tessera/display_window.h>
#include <tessera/serve.h>

#include "access.h"
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

/// The archive a request path names (its first segment, or "NAME" of "/NAME.tess"); empty for
/// the routes that belong to no archive (viewer, health, metrics, the archive list).
std::string_view archiveOfSegments(const std::vector<std::string>& segments);

/// Sets (or with an empty `origin`, removes) the CORS response headers.
void setCorsHeaders(Response& response, const std::string& origin);

/// Thread-safe: the catalog and JSON documents are immutable, the cache and metrics
/// synchronise themselves.
class Router {
 public:
  /// `access` null: every archive is open to every client (the server binds loopback by
  /// default); otherwise its rules guard every archive route (docs/serve.md, "Access control").
  Router(Catalog catalog, const ServeOptions& options, Metrics& metrics,
         std::shared_ptr<const AccessRules> access = nullptr);

  /// Answers `request` from `client` (its address, for rate limits; may be empty). Never
  /// throws; archive failures become 500 with the error's message.
  RoutedResponse handle(const Request& request, std::string_view client = {});

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
  /// The display window of a picture of `image` (?window=, ?gamma=; docs/serve.md); the
  /// error names the parameter. Resolved auto and percentile windows are kept (windows_).
  Result<DisplayWindow> pictureWindow(const ServedArchive& served, uint32_t image,
                                      const Target& target);
  Response picture(const Request& request, const ServedArchive& served, const std::string& key,
                   const std::function<Result<std::string>()>& render, const char* content_type);
  Response viewerFile(const Request& request, std::string_view path);
  Response bytesResponse(const Request& request, std::shared_ptr<const std::string> body,
                         std::string_view content_type, std::string_view etag,
                         std::string_view cache_control);
  Response bytesResponse(const Request& request, BodyPart body, std::string_view content_type,
                         std::string_view etag, std::string_view cache_control);
  void addCommonHeaders(Response& response) const;
  // Access control (router_access.cpp).
  /// The refusal (429, 401 or 403) of a request that may not go on, or nullopt.
  std::optional<Response> refuse(const Request& request, const std::vector<std::string>& segments,
                                 std::string_view client);
  /// /api/archives listing only what the request's credentials may read.
  Response archivesForRequest(const Request& request);
  /// Sets the CORS headers of `archive`'s routes (the access file's origin for it).
  void applyCors(Response& response, std::string_view archive) const;

  const Catalog catalog_;
  const ServeOptions options_;
  Metrics& metrics_;
  TranscodeCache cache_;
  const std::shared_ptr<const AccessRules> access_;
  std::unique_ptr<RateLimiter> limiter_;
  std::shared_ptr<const std::string> archives_json_;
  std::map<std::string, std::shared_ptr<const std::string>> info_json_;  // by archive name
  static constexpr size_t kMaxResolvedWindows = 256;
  std::mutex windows_mutex_;
  std::map<std::string, DisplayWindow> windows_;  ///< resolved windows by archive/image/request
};

}  // namespace tessera::detail
