// Fuzzes `tessera serve`'s request handling as the router sees it (src/serve): the input is a
// raw HTTP/1.1 request, parsed by Beast with the server's limits, then answered by the Router
// over a small archive built at start (tiles, byte ranges, Deep Zoom, XYZ, info.json, the
// viewer's files, metrics). Checks that a parsed request always gets a well-formed answer: a
// status the server may send, a body of the length it declares, and a 206 only for a range.
#include <unistd.h>

#include <filesystem>
#include <memory>

#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/http.hpp>
#include <tessera/build.h>
#include <tessera/serve.h>

#include "format_fuzz_input.h"
#include "metrics.h"
#include "router.h"

namespace {

namespace http = boost::beast::http;

std::unique_ptr<tessera::detail::Metrics> metrics;
std::unique_ptr<tessera::detail::Router> router;
tessera::ServeOptions options;

}  // namespace

extern "C" int LLVMFuzzerInitialize(int* /*argc*/, char*** /*argv*/) {
  using namespace tessera;
  const std::string dir = "/tmp/tessera_http_fuzz_" + std::to_string(::getpid());
  std::filesystem::create_directories(dir);
  BuildOptions build;
  build.inputs = {"synthetic:300x200:5:4"};
  build.output = dir + "/map.tess";
  build.tile_size_px = 64;
  build.codec = Codec::kPng;
  build.threads = 1;
  if (!buildArchive(build)) fuzz::die("http_request_fuzzer", "cannot build the served archive");
  Result<detail::Catalog> catalog = detail::loadCatalog({build.output});
  if (!catalog) fuzz::die("http_request_fuzzer", "cannot open the served archive");
  options.paths = {build.output};
  metrics = std::make_unique<detail::Metrics>();
  router = std::make_unique<detail::Router>(std::move(*catalog), options, *metrics);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace tessera;
  http::request_parser<http::string_body> parser;
  parser.header_limit(options.header_limit_bytes);
  parser.body_limit(options.body_limit_bytes);
  parser.eager(true);
  boost::beast::error_code ec;
  parser.put(boost::asio::buffer(data, size), ec);
  if (ec || !parser.is_done()) return 0;
  detail::RoutedResponse routed = router->handle(parser.get());
  detail::Response& response = routed.response;
  const unsigned status = response.result_int();
  if (status < 200 || status > 599) fuzz::die("http_request_fuzzer", "a status out of range");
  if (status == 206 && parser.get().count(http::field::range) == 0)
    fuzz::die("http_request_fuzzer", "206 without a Range header");
  response.prepare_payload();
  return 0;
}
