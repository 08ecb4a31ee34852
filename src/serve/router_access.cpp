// The router's side of access control: rate limits before anything else, then the access
// file's rules before an archive is even looked up (so a refusal says nothing of whether the
// archive exists), the archive list filtered by credentials, per-archive CORS, and no shared
// caching of protected bytes.
#include <chrono>
#include <cmath>

#include <boost/beast/http/field.hpp>
#include <boost/beast/http/status.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "router.h"

namespace tessera::detail {

namespace http = boost::beast::http;

namespace {

// "address:port" -> "address" (IPv6 addresses hold colons too; the port is after the last).
std::string_view clientAddress(std::string_view peer) {
  const size_t colon = peer.rfind(':');
  return colon == std::string_view::npos ? peer : peer.substr(0, colon);
}

}  // namespace

std::string_view archiveOfSegments(const std::vector<std::string>& segments) {
  if (segments.empty()) return {};
  const std::string& first = segments[0];
  if (segments.size() == 1)
    return first.size() > 5 && first.ends_with(".tess")
               ? std::string_view(first).substr(0, first.size() - 5)
               : std::string_view();
  if (first == "viewer") return {};
  if (first == "api" && segments.size() == 2 && segments[1] == "archives") return {};
  return first;
}

std::optional<Response> Router::refuse(const Request& request,
                                       const std::vector<std::string>& segments,
                                       std::string_view client) {
  const unsigned version = request.version();
  double retry_after_s = 0;
  if (limiter_ &&
      !limiter_->admit(clientAddress(client), std::chrono::steady_clock::now(), &retry_after_s)) {
    Response response = errorResponse(version, http::status::too_many_requests,
                                      "too many requests from this address; retry later");
    response.set(http::field::retry_after,
                 fmt::format("{}", std::max(1, int(std::ceil(retry_after_s)))));
    return response;
  }
  const std::string_view archive = archiveOfSegments(segments);
  if (!access_ || archive.empty()) return std::nullopt;
  const std::string_view target = request.target();
  const size_t q = target.find('?');
  AccessRequest asked;
  asked.archive = archive;
  asked.path = target.substr(0, q);
  asked.query = q == std::string_view::npos ? std::string_view() : target.substr(q + 1);
  asked.authorization = request[http::field::authorization];
  asked.range = request[http::field::range];
  asked.now_unix_s = std::chrono::duration_cast<std::chrono::seconds>(
                         std::chrono::system_clock::now().time_since_epoch())
                         .count();
  const AccessDecision decision = access_->authorize(asked);
  if (decision.verdict == AccessVerdict::kAllowed) return std::nullopt;
  // The body and headers are the same for every archive, existing or not.
  if (decision.verdict == AccessVerdict::kUnauthenticated) {
    Response response = errorResponse(version, http::status::unauthorized,
                                      "a bearer token or a signed URL is needed");
    response.set(http::field::www_authenticate,
                 decision.reason == "unknown token"
                     ? R"(Bearer realm="tessera", error="invalid_token")"
                     : R"(Bearer realm="tessera")");
    return response;
  }
  return errorResponse(version, http::status::forbidden,
                       "the credential does not grant this request");
}

Response Router::archivesForRequest(const Request& request) {
  nlohmann::json list = nlohmann::json::array();
  const std::string_view authorization = request[http::field::authorization];
  for (const auto& [name, served] : catalog_)
    if (access_->mayList(name, authorization))
      list.push_back(
          {{"name", name}, {"url", "/" + name + ".tess"}, {"info", "/" + name + "/info.json"}});
  // Depends on the credentials: never cached by anyone.
  return bytesResponse(
      request,
      std::make_shared<const std::string>(nlohmann::json{{"archives", std::move(list)}}.dump()),
      "application/json", "", "private, no-store");
}

void Router::applyCors(Response& response, std::string_view archive) const {
  if (!access_ || archive.empty()) return;
  setCorsHeaders(response, access_->corsOrigin(archive, options_.cors_origin));
  // A protected archive's bytes may be kept by the client, never by a shared cache, which
  // would hand them to the next requester without asking for a credential.
  if (!access_->isPublic(archive)) {
    const std::string_view cache = response[http::field::cache_control];
    if (cache.starts_with("public"))
      response.set(http::field::cache_control, "private" + std::string(cache.substr(6)));
  }
}

}  // namespace tessera::detail
