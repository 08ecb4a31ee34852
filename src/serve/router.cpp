#include "router.h"

#include <algorithm>
#include <cstdio>
#include <ctime>
#include <functional>
#include <random>

#include <boost/beast/http/field.hpp>
#include <boost/beast/http/status.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "byte_ranges.h"
#include "serve/image_metadata.h"
#include "serve/pictures.h"
#include "viewer_assets.h"

namespace tessera::detail {

namespace http = boost::beast::http;

namespace {

constexpr std::string_view kImmutable = "public, max-age=31536000, immutable";
constexpr std::string_view kRevalidate = "no-cache";

const char* codecContentType(Codec codec) {
  switch (codec) {
    case Codec::kJpeg: return "image/jpeg";
    case Codec::kPng: return "image/png";
    case Codec::kWebp: return "image/webp";
    default: return "application/octet-stream";
  }
}

// The side of a stored tile's payload image: block codecs pad it to whole 4x4 blocks
// (docs/codecs.md), which a client uploading the blocks as stored must size its texture by.
uint32_t payloadSidePx(const ImageInfo& info) {
  const uint32_t side = info.storedTileSidePx();
  const bool blocks = info.default_codec == Codec::kBc1 || info.default_codec == Codec::kBc7;
  return blocks ? (side + 3) / 4 * 4 : side;
}

std::string httpDate(std::time_t time) {
  std::tm parts{};
  ::gmtime_r(&time, &parts);
  char text[64];
  std::strftime(text, sizeof text, "%a, %d %b %Y %H:%M:%S GMT", &parts);
  return text;
}

std::string_view trim(std::string_view text) {
  while (!text.empty() && (text.front() == ' ' || text.front() == '\t')) text.remove_prefix(1);
  while (!text.empty() && (text.back() == ' ' || text.back() == '\t')) text.remove_suffix(1);
  return text;
}

std::string_view opaqueTag(std::string_view tag) {
  if (tag.starts_with("W/")) tag.remove_prefix(2);
  return tag;
}

// If-None-Match uses the weak comparison (RFC 9110, section 13.1.2).
bool ifNoneMatchHits(std::string_view header, std::string_view etag) {
  header = trim(header);
  if (header == "*") return true;
  while (!header.empty()) {
    size_t comma = header.find(',');
    std::string_view item = trim(header.substr(0, comma));
    if (!item.empty() && opaqueTag(item) == opaqueTag(etag)) return true;
    if (comma == std::string_view::npos) break;
    header.remove_prefix(comma + 1);
  }
  return false;
}

// If-Match uses the strong comparison (RFC 9110, section 13.1.1): weak tags never match.
bool strongMatchIn(std::string_view header, std::string_view etag) {
  while (!header.empty()) {
    size_t comma = header.find(',');
    std::string_view item = trim(header.substr(0, comma));
    if (!item.starts_with("W/") && item == etag) return true;
    if (comma == std::string_view::npos) break;
    header.remove_prefix(comma + 1);
  }
  return false;
}

// Strict: digits only, at most 10 of them, and within uint32_t.
std::optional<uint32_t> parseIndex(std::string_view text) {
  if (text.empty() || text.size() > 10) return std::nullopt;
  uint64_t value = 0;
  for (char c : text) {
    if (c < '0' || c > '9') return std::nullopt;
    value = value * 10 + uint64_t(c - '0');
  }
  if (value > UINT32_MAX) return std::nullopt;
  return uint32_t(value);
}

int hexValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

std::string randomBoundary() {
  thread_local std::mt19937_64 generator{std::random_device{}()};
  return fmt::format("tessera-{:016x}{:016x}", generator(), generator());
}

std::string derivedEtag(const ServedArchive& served, std::string_view resource) {
  return fmt::format("\"{:x}\"", std::hash<std::string>{}(served.etag + std::string(resource)));
}

// An archive error for a client: the server's file path becomes the archive's public name
// (clients need not learn the server's layout); the operator gets the full message on stderr.
std::string publicMessage(const ServedArchive& served, const Error& error) {
  std::string message = error.message;
  const std::string public_name = served.name + ".tess";
  for (size_t at = message.find(served.path); at != std::string::npos && !served.path.empty();
       at = message.find(served.path, at + public_name.size()))
    message.replace(at, served.path.size(), public_name);
  return message;
}

void logArchiveError(const Error& error) {
  std::fprintf(stderr, "tessera serve: %s\n", error.message.c_str());
}

}  // namespace

// A request target split into decoded path segments and the one query parameter we read.
struct Router::Target {
  std::vector<std::string> segments;
  std::string format;  // ?format=
  bool has_format = false;
  std::optional<std::string> window, gamma;  // ?window=, ?gamma= (wide images' pictures)
  std::string problem;                       // non-empty: malformed (400)
};

namespace {

Router::Target parseTarget(std::string_view raw) {
  Router::Target target;
  if (raw.empty() || raw.front() != '/') {
    target.problem = "the request target is not an absolute path";
    return target;
  }
  if (raw.find('#') != std::string_view::npos) {
    target.problem = "the request target has a fragment";
    return target;
  }
  std::string_view path = raw, query;
  if (size_t q = raw.find('?'); q != std::string_view::npos) {
    path = raw.substr(0, q);
    query = raw.substr(q + 1);
  }
  path.remove_prefix(1);
  while (!path.empty()) {
    size_t slash = path.find('/');
    std::string_view raw_segment = path.substr(0, slash);
    std::string segment;
    for (size_t i = 0; i < raw_segment.size(); ++i) {
      char c = raw_segment[i];
      if (c == '%') {
        const bool complete = i + 2 < raw_segment.size();
        int high = complete ? hexValue(raw_segment[i + 1]) : -1;
        int low = complete ? hexValue(raw_segment[i + 2]) : -1;
        if (high < 0 || low < 0) {
          target.problem = "bad percent-encoding in the request target";
          return target;
        }
        c = char(high * 16 + low);
        i += 2;
      }
      // No name we serve has these; decoded separators are how traversal hides.
      if (c == '/' || c == '\\' || c == '\0' || uint8_t(c) < 0x20 || c == 0x7f) {
        target.problem = "a path segment holds a separator or control character";
        return target;
      }
      segment += c;
    }
    if (segment == "." || segment == "..") {
      target.problem = "dot segments are not allowed in the request target";
      return target;
    }
    target.segments.push_back(std::move(segment));
    if (slash == std::string_view::npos) break;
    path.remove_prefix(slash + 1);
    if (path.empty()) target.segments.emplace_back();  // a trailing slash
  }
  while (!query.empty()) {
    size_t amp = query.find('&');
    std::string_view pair = query.substr(0, amp);
    if (pair.starts_with("format=")) {
      target.has_format = true;
      target.format = std::string(pair.substr(7));
    } else if (pair.starts_with("window=")) {
      target.window = std::string(pair.substr(7));
    } else if (pair.starts_with("gamma=")) {
      target.gamma = std::string(pair.substr(6));
    }
    if (amp == std::string_view::npos) break;
    query.remove_prefix(amp + 1);
  }
  return target;
}

std::string contentTypeForPath(std::string_view path) {
  size_t dot = path.rfind('.');
  std::string_view ext = dot == std::string_view::npos ? "" : path.substr(dot + 1);
  if (ext == "html" || ext == "htm") return "text/html; charset=utf-8";
  if (ext == "js" || ext == "mjs") return "text/javascript; charset=utf-8";
  if (ext == "css") return "text/css; charset=utf-8";
  if (ext == "json" || ext == "map") return "application/json";
  if (ext == "svg") return "image/svg+xml";
  if (ext == "png") return "image/png";
  if (ext == "jpg" || ext == "jpeg") return "image/jpeg";
  if (ext == "webp") return "image/webp";
  if (ext == "ico") return "image/x-icon";
  if (ext == "wasm") return "application/wasm";
  if (ext == "txt" || ext == "glsl" || ext == "vert" || ext == "frag" || ext == "md")
    return "text/plain; charset=utf-8";
  return "application/octet-stream";
}

std::shared_ptr<const std::string> shared(std::string text) {
  return std::make_shared<const std::string>(std::move(text));
}

}  // namespace

Router::Router(Catalog catalog, const ServeOptions& options, Metrics& metrics,
               std::shared_ptr<const AccessRules> access)
    : catalog_(std::move(catalog)),
      options_(options),
      metrics_(metrics),
      cache_(options.transcode_cache_bytes),
      access_(std::move(access)) {
  if (access_ && access_->requestsPerSecond() > 0)
    limiter_ = std::make_unique<RateLimiter>(access_->requestsPerSecond(), access_->burst());
  nlohmann::json list = nlohmann::json::array();
  for (const auto& [name, served] : catalog_) {
    list.push_back(
        {{"name", name}, {"url", "/" + name + ".tess"}, {"info", "/" + name + "/info.json"}});
    nlohmann::json images = nlohmann::json::array();
    const std::vector<ImageInfo>& infos = served->archive->images();
    for (uint32_t i = 0; i < infos.size(); ++i) {
      const ImageInfo& info = infos[i];
      nlohmann::json levels = nlohmann::json::array();
      for (uint32_t l = 0; l < info.level_count; ++l)
        levels.push_back({{"level", l},
                          {"width", info.levelWidthPx(l)},
                          {"height", info.levelHeightPx(l)},
                          {"tiles_x", info.tilesX(l)},
                          {"tiles_y", info.tilesY(l)}});
      nlohmann::json image = {{"index", i},
                              {"name", info.name},
                              {"width", info.width_px},
                              {"height", info.height_px},
                              {"channels", info.channels},
                              {"sample_type", sampleTypeName(info.sample_type)},
                              {"tile_size", info.tile_size_px},
                              {"border", info.border_px},
                              {"codec", codecName(info.default_codec)},
                              {"tile_content_type", codecContentType(info.default_codec)},
                              {"payload_side", payloadSidePx(info)},
                              {"level_count", info.level_count},
                              {"levels", levels},
                              {"dzi", fmt::format("/{}/{}.dzi", name, i)},
                              {"dzi_max_level", dziMaxLevel(info)},
                              {"xyz", fmt::format("/{}/{}/xyz/{{z}}/{{x}}/{{y}}.png", name, i)},
                              {"xyz_max_zoom", xyzMaxZoom(info)}};
      if (const std::string geo = imageGeoreferenceJson(*served->archive, i); !geo.empty())
        image["georeference"] = nlohmann::json::parse(geo);
      // What pictures of a wide image use without ?window=: the viewer starts from it.
      if (info.sample_type != SampleType::kU8)
        if (Result<DisplayWindow> window = resolveDisplayWindow(*served->archive, i, {}); window)
          image["display_window"] = {{"low", window->low}, {"high", window->high}};
      images.push_back(std::move(image));
    }
    nlohmann::json info = {{"name", name},
                           {"file_bytes", served->file_bytes},
                           {"etag", served->etag},
                           {"archive_url", "/" + name + ".tess"},
                           {"images", images}};
    info_json_[name] = shared(info.dump());
  }
  archives_json_ = shared(nlohmann::json{{"archives", list}}.dump());
}

void setCorsHeaders(Response& response, const std::string& origin) {
  if (origin.empty()) {
    response.erase(http::field::access_control_allow_origin);
    response.erase(http::field::access_control_expose_headers);
    response.erase(http::field::vary);
    return;
  }
  response.set(http::field::access_control_allow_origin, origin);
  response.set(http::field::access_control_expose_headers,
               "ETag, Content-Range, Content-Length, Accept-Ranges, X-Tessera-Codec, "
               "X-Tessera-Tile-Kind, WWW-Authenticate, Retry-After");
  if (origin != "*")
    response.set(http::field::vary, "Origin");
  else
    response.erase(http::field::vary);
}

void Router::addCommonHeaders(Response& response) const {
  response.set(http::field::server, "tessera");
  if (!options_.cors_origin.empty()) setCorsHeaders(response, options_.cors_origin);
}

Response Router::errorResponse(unsigned version, http::status status,
                               std::string_view reason) const {
  Response response{status, version};
  addCommonHeaders(response);
  response.set(http::field::content_type, "text/plain; charset=utf-8");
  response.set(http::field::cache_control, "no-store");
  response.body().push_back(BodyPart::text(
      fmt::format("{} {}: {}\n", unsigned(status), http::obsolete_reason(status), reason)));
  response.prepare_payload();
  return response;
}

Response Router::bytesResponse(const Request& request, std::shared_ptr<const std::string> body,
                               std::string_view content_type, std::string_view etag,
                               std::string_view cache_control) {
  return bytesResponse(request, BodyPart::text(std::move(body)), content_type, etag, cache_control);
}

Response Router::bytesResponse(const Request& request, BodyPart body, std::string_view content_type,
                               std::string_view etag, std::string_view cache_control) {
  Response response{http::status::ok, request.version()};
  addCommonHeaders(response);
  if (!etag.empty()) response.set(http::field::etag, etag);
  if (!cache_control.empty()) response.set(http::field::cache_control, cache_control);
  if (!etag.empty() && ifNoneMatchHits(request[http::field::if_none_match], etag)) {
    response.result(http::status::not_modified);
    return response;
  }
  response.set(http::field::content_type, content_type);
  response.body().push_back(std::move(body));
  response.prepare_payload();
  return response;
}

RoutedResponse Router::handle(const Request& request, std::string_view client) {
  const http::verb method = request.method();
  Target target = parseTarget(request.target());
  const std::string_view archive = archiveOfSegments(target.segments);
  if (method == http::verb::options) {
    Response response{http::status::no_content, request.version()};
    addCommonHeaders(response);
    applyCors(response, archive);
    response.set(http::field::allow, "GET, HEAD, OPTIONS");
    if (response.count(http::field::access_control_allow_origin)) {
      response.set(http::field::access_control_allow_methods, "GET, HEAD, OPTIONS");
      response.set(http::field::access_control_allow_headers,
                   access_ ? "Range, If-None-Match, If-Range, If-Modified-Since, Authorization"
                           : "Range, If-None-Match, If-Range, If-Modified-Since");
      response.set(http::field::access_control_max_age, "86400");
    }
    return {Endpoint::kOther, std::move(response)};
  }
  if (method != http::verb::get && method != http::verb::head) {
    Response response = errorResponse(request.version(), http::status::method_not_allowed,
                                      "only GET, HEAD and OPTIONS are served");
    response.set(http::field::allow, "GET, HEAD, OPTIONS");
    return {Endpoint::kOther, std::move(response)};
  }
  RoutedResponse routed;
  if (!target.problem.empty()) {
    routed = {Endpoint::kOther,
              errorResponse(request.version(), http::status::bad_request, target.problem)};
  } else if (std::optional<Response> refused = refuse(request, target.segments, client)) {
    routed = {Endpoint::kOther, std::move(*refused)};
  } else {
    routed = route(request, target);
  }
  applyCors(routed.response, archive);
  if (method == http::verb::head) {
    // Same header as GET, Content-Length included, and no body.
    const uint64_t length = PartsBody::size(routed.response.body());
    routed.response.body().clear();
    if (routed.response.result() != http::status::not_modified &&
        routed.response.result() != http::status::no_content)
      routed.response.content_length(length);
  }
  return routed;
}

namespace {

// The display window a picture's query asks for: ?window= (MIN,MAX, pLOW,pHIGH or auto, the
// default) and ?gamma= (default 1). The error names the parameter: the answer is a 400.
Result<DisplayWindowRequest> pictureWindowRequest(const Router::Target& target) {
  DisplayWindowRequest request;
  if (target.window) {
    if (Result<void> parsed = parseDisplayWindow(*target.window, request); !parsed)
      return fail(ErrorCode::kInvalidArgument, "query parameter window: " + parsed.error().message);
  }
  if (target.gamma) {
    Result<double> gamma = parseGamma(*target.gamma);
    if (!gamma)
      return fail(ErrorCode::kInvalidArgument, "query parameter gamma: " + gamma.error().message);
    request.gamma = *gamma;
  }
  return request;
}

// What a picture's cache key and ETag add for its window (exact: hexadecimal floats).
std::string windowKey(const DisplayWindow& window) {
  return fmt::format("/{:a},{:a},{:a}", window.low, window.high, window.gamma);
}

}  // namespace

Result<DisplayWindow> Router::pictureWindow(const ServedArchive& served, uint32_t image,
                                            const Target& target) {
  TESSERA_ASSIGN_OR_RETURN(DisplayWindowRequest request, pictureWindowRequest(target));
  const Archive& archive = *served.archive;
  if (archive.images()[image].sample_type == SampleType::kU8) return DisplayWindow{};
  if (request.kind == DisplayWindowRequest::Kind::kValues)
    return resolveDisplayWindow(archive, image, request);
  // auto and percentiles read the metadata or a coarse level: once per archive, image and
  // request, not once per tile. Clients choose the percentiles, so the map is bounded.
  const std::string key = fmt::format("{}/{}/{}/{:a}/{:a}", served.name, image, int(request.kind),
                                      request.first, request.second);
  {
    std::lock_guard lock(windows_mutex_);
    if (auto it = windows_.find(key); it != windows_.end()) {
      DisplayWindow window = it->second;
      window.gamma = request.gamma;
      return window;
    }
  }
  TESSERA_ASSIGN_OR_RETURN(DisplayWindow window, resolveDisplayWindow(archive, image, request));
  std::lock_guard lock(windows_mutex_);
  if (windows_.size() >= kMaxResolvedWindows) windows_.clear();
  windows_[key] = window;
  return window;
}

RoutedResponse Router::route(const Request& request, const Target& target) {
  const std::vector<std::string>& seg = target.segments;
  const unsigned version = request.version();
  auto notFound = [&](Endpoint endpoint, std::string_view why) {
    return RoutedResponse{endpoint, errorResponse(version, http::status::not_found, why)};
  };
  auto badRequest = [&](Endpoint endpoint, std::string_view why) {
    return RoutedResponse{endpoint, errorResponse(version, http::status::bad_request, why)};
  };
  if (seg.empty()) return {Endpoint::kViewer, viewerFile(request, "index.html")};
  if (seg[0] == "viewer" && seg.size() >= 2) {
    std::string path = seg[1];
    for (size_t i = 2; i < seg.size(); ++i) path += "/" + seg[i];
    return {Endpoint::kViewer, viewerFile(request, path)};
  }
  if (seg.size() == 1 && seg[0] == "healthz")
    return {Endpoint::kHealth,
            bytesResponse(request, shared("ok"), "text/plain; charset=utf-8", "", "no-store")};
  if (seg.size() == 1 && seg[0] == "metrics")
    return {Endpoint::kMetrics,
            bytesResponse(request, shared(metrics_.render(cache_.stats())),
                          "text/plain; version=0.0.4; charset=utf-8", "", "no-store")};
  if (seg.size() == 2 && seg[0] == "api" && seg[1] == "archives" && access_)
    return {Endpoint::kArchives, archivesForRequest(request)};
  if (seg.size() == 2 && seg[0] == "api" && seg[1] == "archives")
    return {Endpoint::kArchives,
            bytesResponse(request, archives_json_, "application/json",
                          derivedEtag(ServedArchive{}, *archives_json_), kRevalidate)};
  if (seg.size() == 1 && seg[0].size() > 5 && seg[0].ends_with(".tess")) {
    auto it = catalog_.find(seg[0].substr(0, seg[0].size() - 5));
    if (it == catalog_.end()) return notFound(Endpoint::kArchiveFile, "no such archive");
    if (!it->second->unchangedOnDisk())
      return {Endpoint::kArchiveFile, changedOnDisk(version, *it->second)};
    return {Endpoint::kArchiveFile, archiveFile(request, *it->second)};
  }
  if (seg.size() < 2) return notFound(Endpoint::kOther, "no such resource");
  auto it = catalog_.find(seg[0]);
  if (it == catalog_.end()) return notFound(Endpoint::kOther, "no such archive");
  const ServedArchive& served = *it->second;
  if (!served.unchangedOnDisk()) return {Endpoint::kOther, changedOnDisk(version, served)};
  const Archive& archive = *served.archive;
  const int quality = options_.jpeg_quality;

  if (seg.size() == 2 && seg[1] == "info.json")
    return {Endpoint::kInfo, bytesResponse(request, info_json_.at(served.name), "application/json",
                                           served.etag, kRevalidate)};
  if (seg.size() == 2 && seg[1].ends_with(".dzi")) {
    std::optional<uint32_t> image = parseIndex(seg[1].substr(0, seg[1].size() - 4));
    if (!image) return badRequest(Endpoint::kDzi, "the image index is not a number");
    if (*image >= archive.images().size()) return notFound(Endpoint::kDzi, "no such image");
    return {Endpoint::kDzi, dziDescriptor(request, served, *image)};
  }
  if (seg.size() == 4 && seg[1].ends_with("_files")) {
    std::optional<uint32_t> image = parseIndex(seg[1].substr(0, seg[1].size() - 6));
    std::optional<uint32_t> level = parseIndex(seg[2]);
    const std::string& name = seg[3];
    size_t underscore = name.find('_'), dot = name.rfind('.');
    if (underscore == std::string::npos || dot == std::string::npos || dot < underscore)
      return badRequest(Endpoint::kDziTile, "a Deep Zoom tile is <col>_<row>.<jpg|png>");
    std::optional<uint32_t> col = parseIndex(std::string_view(name).substr(0, underscore));
    std::optional<uint32_t> row =
        parseIndex(std::string_view(name).substr(underscore + 1, dot - underscore - 1));
    std::optional<PictureFormat> format =
        parsePictureFormat(std::string_view(name).substr(dot + 1));
    if (!image || !level || !col || !row)
      return badRequest(Endpoint::kDziTile, "a Deep Zoom index is not a number");
    if (!format) return notFound(Endpoint::kDziTile, "Deep Zoom tiles are .jpg or .png");
    if (*image >= archive.images().size()) return notFound(Endpoint::kDziTile, "no such image");
    Result<DisplayWindow> window = pictureWindow(served, *image, target);
    if (!window) return badRequest(Endpoint::kDziTile, window.error().message);
    const std::string key =
        fmt::format("dzi/{}/{}/{}/{}/{}", *image, *level, *col, *row, int(*format)) +
        windowKey(*window);
    return {Endpoint::kDziTile, picture(
                                    request, served, key,
                                    [&]() -> Result<std::string> {
                                      TESSERA_ASSIGN_OR_RETURN(
                                          Picture out,
                                          renderDziTile(archive, *image, *level, *col, *row,
                                                        *format, quality, *window));
                                      return std::move(out.bytes);
                                    },
                                    pictureContentType(*format))};
  }
  if (seg.size() == 6 && seg[2] == "xyz") {
    std::optional<uint32_t> image = parseIndex(seg[1]);
    std::optional<uint32_t> z = parseIndex(seg[3]);
    std::optional<uint32_t> x = parseIndex(seg[4]);
    size_t dot = seg[5].rfind('.');
    if (dot == std::string::npos) return badRequest(Endpoint::kXyz, "XYZ tiles are <y>.<png|jpg>");
    std::optional<uint32_t> y = parseIndex(std::string_view(seg[5]).substr(0, dot));
    std::optional<PictureFormat> format =
        parsePictureFormat(std::string_view(seg[5]).substr(dot + 1));
    if (!image || !z || !x || !y) return badRequest(Endpoint::kXyz, "an XYZ index is not a number");
    if (!format) return notFound(Endpoint::kXyz, "XYZ tiles are .png or .jpg");
    if (*image >= archive.images().size()) return notFound(Endpoint::kXyz, "no such image");
    Result<DisplayWindow> window = pictureWindow(served, *image, target);
    if (!window) return badRequest(Endpoint::kXyz, window.error().message);
    const std::string key =
        fmt::format("xyz/{}/{}/{}/{}/{}", *image, *z, *x, *y, int(*format)) + windowKey(*window);
    return {Endpoint::kXyz, picture(
                                request, served, key,
                                [&]() -> Result<std::string> {
                                  TESSERA_ASSIGN_OR_RETURN(
                                      Picture out, renderXyzTile(archive, *image, *z, *x, *y,
                                                                 *format, quality, *window));
                                  return std::move(out.bytes);
                                },
                                pictureContentType(*format))};
  }
  if (seg.size() == 5) return {Endpoint::kTile, tile(request, served, target)};
  return notFound(Endpoint::kOther, "no such resource");
}

Response Router::picture(const Request& request, const ServedArchive& served,
                         const std::string& key, const std::function<Result<std::string>()>& render,
                         const char* content_type) {
  const std::string cache_key = served.name + "/" + key;
  std::shared_ptr<const std::string> body = cache_.find(cache_key);
  const std::string etag = derivedEtag(served, key);
  if (!body) {
    // A conditional request for something never rendered still needs no rendering.
    if (ifNoneMatchHits(request[http::field::if_none_match], etag)) {
      Response response{http::status::not_modified, request.version()};
      addCommonHeaders(response);
      response.set(http::field::etag, etag);
      response.set(http::field::cache_control, kImmutable);
      return response;
    }
    Result<std::string> rendered = render();
    if (!rendered) {
      const Error& error = rendered.error();
      if (error.code == ErrorCode::kNotFound)
        return errorResponse(request.version(), http::status::not_found,
                             publicMessage(served, error));
      if (error.code == ErrorCode::kInvalidArgument)
        return errorResponse(request.version(), http::status::not_found,
                             publicMessage(served, error));
      logArchiveError(error);
      metrics_.recordError(ServeError::kArchive);
      return errorResponse(request.version(), http::status::internal_server_error,
                           publicMessage(served, error));
    }
    body = shared(std::move(*rendered));
    cache_.insert(cache_key, body);
  }
  return bytesResponse(request, std::move(body), content_type, etag, kImmutable);
}

Response Router::dziDescriptor(const Request& request, const ServedArchive& served,
                               uint32_t image) {
  const ImageInfo& info = served.archive->images()[image];
  std::string xml = detail::dziDescriptor(info);
  return bytesResponse(request, shared(std::move(xml)), "application/xml",
                       derivedEtag(served, fmt::format("dzi/{}", image)), kRevalidate);
}

Response Router::tile(const Request& request, const ServedArchive& served, const Target& target) {
  const std::vector<std::string>& seg = target.segments;
  const unsigned version = request.version();
  std::optional<uint32_t> image = parseIndex(seg[1]), level = parseIndex(seg[2]),
                          x = parseIndex(seg[3]), y = parseIndex(seg[4]);
  if (!image || !level || !x || !y)
    return errorResponse(version, http::status::bad_request,
                         "a tile address is /<archive>/<image>/<level>/<x>/<y> in decimal");
  const Archive& archive = *served.archive;
  if (*image >= archive.images().size())
    return errorResponse(version, http::status::not_found, "no such image");
  const ImageInfo& info = archive.images()[*image];
  if (*level >= info.level_count || *x >= info.tilesX(*level) || *y >= info.tilesY(*level))
    return errorResponse(
        version, http::status::not_found,
        fmt::format("tile ({},{},{}) is outside image {}'s pyramid", *level, *x, *y, *image));
  const TileId id{*image, *level, *x, *y};
  if (target.has_format) {
    std::optional<PictureFormat> format = parsePictureFormat(target.format);
    if (!format) return errorResponse(version, http::status::bad_request, "format is png or jpeg");
    Result<DisplayWindow> window = pictureWindow(served, *image, target);
    if (!window) return errorResponse(version, http::status::bad_request, window.error().message);
    const std::string key = fmt::format("tile/{}/{}/{}/{}/{}/{:a},{:a},{:a}", *image, *level, *x,
                                        *y, int(*format), window->low, window->high, window->gamma);
    Response response = picture(
        request, served, key,
        [&]() -> Result<std::string> {
          TESSERA_ASSIGN_OR_RETURN(
              Picture out,
              transcodeStoredTile(archive, id, *format, options_.jpeg_quality, *window));
          return std::move(out.bytes);
        },
        pictureContentType(*format));
    if (response.result() == http::status::ok || response.result() == http::status::not_modified)
      response.set("X-Tessera-Codec", *format == PictureFormat::kPng ? "png" : "jpeg");
    return response;
  }
  Result<TileEntry> entry = archive.tileEntry(id);
  if (!entry) {
    metrics_.recordError(ServeError::kArchive);
    logArchiveError(entry.error());
    return errorResponse(version, http::status::internal_server_error,
                         publicMessage(served, entry.error()));
  }
  Response response{http::status::ok, version};
  addCommonHeaders(response);
  response.set(http::field::cache_control, kImmutable);
  response.set("X-Tessera-Tile-Kind", tileKindName(entry->kind));
  if (entry->kind != TileKind::kEncoded) {
    // No payload to send: the kind (and colour) say everything; ?format= gives pixels. A
    // procedural tile's instance page is no picture: readers of the archive file fetch it by
    // range and composite it, and ?format= gives its composited pixels.
    response.result(http::status::no_content);
    if (entry->kind == TileKind::kUniform) {
      // Channel 0 first (rrggbbaa), the order people read colours in, whatever the
      // in-memory byte order of uniform_rgba.
      const uint32_t rgba = entry->uniform_rgba;
      response.set("X-Tessera-Uniform-Rgba",
                   fmt::format("{:02x}{:02x}{:02x}{:02x}", rgba & 0xff, (rgba >> 8) & 0xff,
                               (rgba >> 16) & 0xff, rgba >> 24));
    }
    response.set(http::field::etag,
                 fmt::format("\"{}-{:08x}\"", tileKindName(entry->kind), entry->uniform_rgba));
    return response;
  }
  const std::string etag = fmt::format("\"{:016x}\"", entry->checksum);
  response.set(http::field::etag, etag);
  response.set("X-Tessera-Codec", codecName(entry->codec));
  if (ifNoneMatchHits(request[http::field::if_none_match], etag)) {
    response.result(http::status::not_modified);
    return response;
  }
  Result<std::vector<uint8_t>> payload = archive.readPayload(id, *entry);
  if (!payload) {
    metrics_.recordError(ServeError::kArchive);
    logArchiveError(payload.error());
    return errorResponse(version, http::status::internal_server_error,
                         publicMessage(served, payload.error()));
  }
  response.set(http::field::content_type, codecContentType(entry->codec));
  response.body().push_back(BodyPart::payload(std::move(*payload)));
  response.prepare_payload();
  return response;
}

Response Router::changedOnDisk(unsigned version, const ServedArchive& served) const {
  // Logged on every request, which is what an operator who rewrote a served file needs to see.
  std::fprintf(stderr,
               "tessera serve: %s changed on disk since the server started; restart to serve it\n",
               served.path.c_str());
  return errorResponse(version, http::status::service_unavailable,
                       fmt::format("archive {} changed on disk since the server started; the "
                                   "server must be restarted to serve it",
                                   served.name));
}

Response Router::archiveFile(const Request& request, const ServedArchive& served) {
  const unsigned version = request.version();
  const uint64_t size = served.file_bytes;
  const std::string last_modified = httpDate(served.modified);
  Response response{http::status::ok, version};
  addCommonHeaders(response);
  response.set(http::field::accept_ranges, "bytes");
  response.set(http::field::etag, served.etag);
  response.set(http::field::last_modified, last_modified);
  response.set(http::field::cache_control, kRevalidate);
  // If-Match (RFC 9110, 13.1.1): a client holding bytes of one version asks for more of that
  // version only; any other version is 412, never bytes to mix with what it has.
  if (std::string_view if_match = trim(request[http::field::if_match]);
      !if_match.empty() && if_match != "*" && !strongMatchIn(if_match, served.etag)) {
    Response refused =
        errorResponse(version, http::status::precondition_failed,
                      fmt::format("{}.tess is not the version asked for (If-Match); it is now {}",
                                  served.name, served.etag));
    refused.set(http::field::etag, served.etag);
    return refused;
  }
  if (ifNoneMatchHits(request[http::field::if_none_match], served.etag)) {
    response.result(http::status::not_modified);
    return response;
  }
  auto whole = [&]() {
    response.set(http::field::content_type, "application/octet-stream");
    response.body().push_back(BodyPart::file(served.source, 0, size));
    response.prepare_payload();
    return std::move(response);
  };
  std::string_view range_header = request[http::field::range];
  if (range_header.empty() || request.method() != http::verb::get) return whole();
  // If-Range: a strong ETag compared strongly, or the exact Last-Modified date.
  if (std::string_view if_range = trim(request[http::field::if_range]); !if_range.empty()) {
    const bool matches =
        if_range.starts_with("\"") ? if_range == served.etag : if_range == last_modified;
    if (!matches) return whole();
  }
  RangeRequest ranges = parseRangeHeader(range_header, size, options_.max_ranges);
  switch (ranges.verdict) {
    case RangeVerdict::kIgnore: return whole();
    case RangeVerdict::kUnsatisfiable:
    case RangeVerdict::kTooManyRanges: {
      Response refused = errorResponse(
          version, http::status::range_not_satisfiable,
          ranges.verdict == RangeVerdict::kTooManyRanges
              ? fmt::format("more than {} ranges", options_.max_ranges)
              : fmt::format("no range overlaps the {} bytes of {}.tess", size, served.name));
      refused.set(http::field::content_range, fmt::format("bytes */{}", size));
      refused.set(http::field::accept_ranges, "bytes");
      return refused;
    }
    case RangeVerdict::kSatisfiable: break;
  }
  response.result(http::status::partial_content);
  if (ranges.ranges.size() == 1) {
    const ResolvedRange& range = ranges.ranges[0];
    response.set(http::field::content_type, "application/octet-stream");
    response.set(http::field::content_range,
                 fmt::format("bytes {}-{}/{}", range.first, range.first + range.length - 1, size));
    response.body().push_back(BodyPart::file(served.source, range.first, range.length));
    response.prepare_payload();
    return response;
  }
  const std::string boundary = randomBoundary();
  response.set(http::field::content_type, "multipart/byteranges; boundary=" + boundary);
  for (size_t i = 0; i < ranges.ranges.size(); ++i) {
    const ResolvedRange& range = ranges.ranges[i];
    response.body().push_back(BodyPart::text(fmt::format(
        "{}--{}\r\nContent-Type: application/octet-stream\r\n"
        "Content-Range: bytes {}-{}/{}\r\n\r\n",
        i == 0 ? "" : "\r\n", boundary, range.first, range.first + range.length - 1, size)));
    response.body().push_back(BodyPart::file(served.source, range.first, range.length));
  }
  response.body().push_back(BodyPart::text(fmt::format("\r\n--{}--\r\n", boundary)));
  response.prepare_payload();
  return response;
}

Response Router::viewerFile(const Request& request, std::string_view path) {
  std::span<const EmbeddedFile> files = viewerAssets();
  auto it =
      std::lower_bound(files.begin(), files.end(), path,
                       [](const EmbeddedFile& file, std::string_view p) { return file.path < p; });
  if (it == files.end() || it->path != path)
    return errorResponse(request.version(), http::status::not_found,
                         fmt::format("the viewer has no file {}", path));
  return bytesResponse(request, BodyPart::staticBytes(it->bytes), contentTypeForPath(path),
                       fmt::format("\"{:x}\"", std::hash<std::string_view>{}(it->bytes)),
                       kRevalidate);
}

}  // namespace tessera::detail
