// TileServer: the accept loop and one Connection per socket, over Boost.Beast and Asio. Each
// connection lives on one I/O thread's io_context; request handling (pread, decode, encode)
// runs there too, which is cheap for stored tiles and bounded for transcodes by the cache.
#include <tessera/serve.h>

#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <ctime>
#include <mutex>
#include <optional>
#include <thread>
#include <unordered_map>

#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/dispatch.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/core/string.hpp>
#include <boost/beast/core/tcp_stream.hpp>
#include <boost/beast/http/error.hpp>
#include <boost/beast/http/read.hpp>
#include <boost/beast/http/serializer.hpp>
#include <boost/beast/http/write.hpp>
#include <fmt/format.h>

#include "router.h"

namespace tessera {

namespace net = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
using tcp = net::ip::tcp;
using Clock = std::chrono::steady_clock;

namespace {

// `target` with the value of its query's `sig` parameter replaced by REDACTED.
std::string withoutSignature(std::string_view target) {
  std::string out(target);
  const size_t query = out.find('?');
  if (query == std::string::npos) return out;
  for (size_t at = out.find("sig=", query); at != std::string::npos;
       at = out.find("sig=", at + 1)) {
    if (out[at - 1] != '?' && out[at - 1] != '&') continue;
    const size_t end = std::min(out.find('&', at), out.size());
    out.replace(at + 4, end - at - 4, "REDACTED");
  }
  return out;
}

class AccessLog {
 public:
  Result<void> open(const std::string& path) {
    if (path.empty()) return {};
    if (path == "-") {
      file_ = stdout;
      return {};
    }
    file_ = std::fopen(path.c_str(), "a");
    owned_ = file_ != nullptr;
    if (!file_) return fail(ErrorCode::kIo, fmt::format("{}: cannot open the access log", path));
    return {};
  }
  ~AccessLog() {
    if (owned_) std::fclose(file_);
  }
  bool enabled() const { return file_ != nullptr; }
  void write(const std::string& peer, std::string_view method, std::string_view target,
             unsigned status, uint64_t bytes, int64_t micros) {
    if (!file_) return;
    const auto now = std::chrono::system_clock::now();
    const std::time_t seconds = std::chrono::system_clock::to_time_t(now);
    const int millis =
        int(std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count() %
            1000);
    std::tm parts{};
    ::gmtime_r(&seconds, &parts);
    char stamp[32];
    std::strftime(stamp, sizeof stamp, "%Y-%m-%dT%H:%M:%S", &parts);
    // Targets are logged as received, minus anything that could break the line format and
    // the signature of a signed URL (a credential until it expires).
    std::string safe_target = withoutSignature(target.substr(0, 2048));
    for (char& c : safe_target)
      if (uint8_t(c) < 0x21 || uint8_t(c) >= 0x7f) c = '?';
    std::string line = fmt::format("{}.{:03d}Z {} {} {} {} {} {}\n", stamp, millis, peer,
                                   method.empty() ? "-" : method,
                                   safe_target.empty() ? "-" : safe_target, status, bytes, micros);
    std::lock_guard lock(mutex_);
    std::fwrite(line.data(), 1, line.size(), file_);
    std::fflush(file_);
  }

 private:
  std::mutex mutex_;  // guards writes to file_
  std::FILE* file_ = nullptr;
  bool owned_ = false;
};

}  // namespace

class Connection;

struct TileServer::Impl {
  ServeOptions options;
  detail::Metrics metrics;
  std::unique_ptr<detail::Router> router;
  AccessLog access_log;
  std::atomic<bool> stopping{false};
  std::mutex registry_mutex;  // guards connections; taken after no other lock
  std::condition_variable registry_changed;
  std::unordered_map<Connection*, std::weak_ptr<Connection>> connections;
  // One io_context per thread, each run by that thread alone (nginx's worker model): a
  // connection's handlers never change threads, so it needs no strand and a request wakes no
  // other thread. Connections are dealt to the contexts in turn as they are accepted.
  // Declared after everything a connection touches: destroying a context destroys the
  // handlers that still own connections, whose destructors use the members above.
  std::vector<std::unique_ptr<net::io_context>> contexts;
  std::vector<net::executor_work_guard<net::io_context::executor_type>> keep_running;
  std::unique_ptr<tcp::acceptor> acceptor;          // on contexts[0]
  std::unique_ptr<net::steady_timer> accept_retry;  // on contexts[0]
  uint32_t next_context = 0;                        // used by the accept handler only
  std::vector<std::thread> threads;
  uint16_t port = 0;
  std::string address;
  bool stopped = false;
  std::mutex stop_mutex;  // serialises stop()

  void accept();
};

class Connection : public std::enable_shared_from_this<Connection> {
 public:
  Connection(TileServer::Impl& server, tcp::socket socket)
      : server_(server), stream_(std::move(socket)) {
    beast::error_code ec;
    tcp::endpoint remote = stream_.socket().remote_endpoint(ec);
    peer_ = ec ? "-" : fmt::format("{}:{}", remote.address().to_string(), remote.port());
    server_.metrics.connectionOpened();
  }
  ~Connection() {
    server_.metrics.connectionClosed();
    std::lock_guard lock(server_.registry_mutex);
    server_.connections.erase(this);
    server_.registry_changed.notify_all();
  }

  void start() {
    {
      std::lock_guard lock(server_.registry_mutex);
      server_.connections[this] = weak_from_this();
    }
    net::dispatch(stream_.get_executor(), [self = shared_from_this()] { self->waitForRequest(); });
  }

  /// From any thread: closes the connection if it is waiting for a request, otherwise after
  /// the response in progress. `force` closes it whatever it is doing.
  void requestStop(bool force) {
    net::post(stream_.get_executor(), [self = shared_from_this(), force] {
      self->stop_requested_ = true;
      if (force || self->idle_) {
        beast::error_code ignored;
        self->stream_.socket().close(ignored);
      }
    });
  }

 private:
  using Request = detail::Request;
  const ServeOptions& options() const { return server_.options; }

  void waitForRequest() {
    if (stop_requested_) return close();
    // Bytes already buffered (a pipelined request) start the next request at once; otherwise
    // the idle timeout runs until its first byte arrives, then the header timeout.
    if (buffer_.size() > 0) return readHeader();
    idle_ = true;
    stream_.expires_after(std::chrono::milliseconds(options().idle_timeout_ms));
    stream_.async_read_some(buffer_.prepare(4096),
                            [self = shared_from_this()](beast::error_code ec, size_t bytes) {
                              self->idle_ = false;
                              if (ec) return self->onSocketError(ec);
                              self->buffer_.commit(bytes);
                              self->readHeader();
                            });
  }

  void readHeader() {
    parser_.emplace();
    parser_->header_limit(options().header_limit_bytes);
    parser_->body_limit(options().body_limit_bytes);
    stream_.expires_after(std::chrono::milliseconds(options().header_timeout_ms));
    http::async_read_header(stream_, buffer_, *parser_,
                            [self = shared_from_this()](beast::error_code ec, size_t bytes) {
                              self->onHeader(ec, bytes);
                            });
  }

  void onHeader(beast::error_code ec, size_t header_bytes) {
    if (ec) return onReadError(ec);
    started_ = Clock::now();
    // Beast bounds the bytes it scans for the end of a header, not a complete header that
    // arrived in one read; the limit applies to both.
    if (header_bytes > options().header_limit_bytes)
      return refuse(
          http::status::request_header_fields_too_large,
          fmt::format("the request header exceeds {} bytes", options().header_limit_bytes));
    const Request& request = parser_->get();
    // Request smuggling: a message with both framings is refused outright (RFC 9112,
    // section 6.1 allows treating it as an error, and a front end may disagree on which wins).
    if (request.count(http::field::content_length) > 0 &&
        request.count(http::field::transfer_encoding) > 0)
      return refuse(http::status::bad_request,
                    "both Content-Length and Transfer-Encoding are present");
    if (request.count(http::field::content_length) > 1)
      return refuse(http::status::bad_request, "more than one Content-Length field");
    // Only "chunked" is understood; anything else would leave the body's end unknown.
    if (request.count(http::field::transfer_encoding) > 0 &&
        !beast::iequals(request[http::field::transfer_encoding], "chunked"))
      return refuse(http::status::not_implemented,
                    "the only transfer coding accepted in requests is chunked");
    if (!parser_->is_done()) {
      stream_.expires_after(std::chrono::milliseconds(options().body_timeout_ms));
      http::async_read(stream_, buffer_, *parser_,
                       [self = shared_from_this()](beast::error_code read_ec, size_t) {
                         if (read_ec) return self->onReadError(read_ec);
                         self->handle();
                       });
      return;
    }
    handle();
  }

  void handle() {
    const Request& request = parser_->get();
    detail::RoutedResponse routed = server_.router->handle(request, peer_);
    endpoint_ = routed.endpoint;
    method_ = std::string(request.method_string());
    target_ = std::string(request.target());
    head_ = request.method() == http::verb::head;
    const bool keep_alive = request.keep_alive() && !stop_requested_ &&
                            !server_.stopping.load(std::memory_order_relaxed);
    response_ = std::move(routed.response);
    response_.keep_alive(keep_alive);
    write();
  }

  // Answers a malformed request and closes: after a framing error the rest of the stream
  // cannot be trusted to start a request.
  void refuse(http::status status, std::string_view reason) {
    server_.metrics.recordError(detail::ServeError::kParse);
    if (!parser_ || !parser_->is_header_done()) started_ = Clock::now();
    endpoint_ = detail::Endpoint::kOther;
    if (parser_ && parser_->is_header_done()) {
      method_ = std::string(parser_->get().method_string());
      target_ = std::string(parser_->get().target());
    } else {
      method_.clear();
      target_.clear();
    }
    head_ = false;
    response_ = server_.router->errorResponse(11, status, reason);
    response_.keep_alive(false);
    write();
  }

  void write() {
    serializer_.emplace(response_);
    writeSome();
  }

  // The send timeout runs per write, not per response: a large archive download to a slow but
  // live client keeps going, while a client that stops reading is closed.
  void writeSome() {
    stream_.expires_after(std::chrono::milliseconds(options().send_timeout_ms));
    http::async_write_some(stream_, *serializer_,
                           [self = shared_from_this()](beast::error_code ec, size_t) {
                             if (!ec && !self->serializer_->is_done()) return self->writeSome();
                             self->onWritten(ec);
                           });
  }

  void onWritten(beast::error_code ec) {
    const int64_t micros =
        std::chrono::duration_cast<std::chrono::microseconds>(Clock::now() - started_).count();
    const uint64_t body_bytes = head_ ? 0 : detail::PartsBody::size(response_.body());
    const unsigned status = response_.result_int();
    server_.metrics.recordResponse(endpoint_, status, ec ? 0 : body_bytes, double(micros) / 1e6);
    server_.access_log.write(peer_, method_, target_, status, ec ? 0 : body_bytes, micros);
    const bool keep_alive = response_.keep_alive();
    serializer_.reset();
    response_ = {};
    if (ec) return onSocketError(ec);
    if (!keep_alive) return lingeringClose();
    waitForRequest();
  }

  void onReadError(beast::error_code ec) {
    if (ec == http::error::header_limit)
      return refuse(
          http::status::request_header_fields_too_large,
          fmt::format("the request header exceeds {} bytes", options().header_limit_bytes));
    if (ec == http::error::body_limit)
      return refuse(http::status::payload_too_large,
                    fmt::format("the request body exceeds {} bytes", options().body_limit_bytes));
    if (ec == http::error::end_of_stream || ec == http::error::partial_message ||
        ec == beast::error::timeout || ec == net::error::operation_aborted ||
        ec == net::error::connection_reset || ec == net::error::eof ||
        ec == net::error::bad_descriptor)
      return onSocketError(ec);
    if (ec.category() == http::make_error_code(http::error::bad_method).category())
      return refuse(http::status::bad_request, fmt::format("malformed request: {}", ec.message()));
    onSocketError(ec);
  }

  void onSocketError(beast::error_code ec) {
    if (ec == beast::error::timeout) {
      server_.metrics.recordError(detail::ServeError::kTimeout);
    } else if (ec != http::error::end_of_stream && ec != net::error::eof &&
               ec != net::error::operation_aborted && ec != net::error::connection_reset &&
               ec != net::error::bad_descriptor && ec != http::error::partial_message) {
      server_.metrics.recordError(detail::ServeError::kIo);
    }
    close();
  }

  void close() {
    beast::error_code ignored;
    stream_.socket().close(ignored);
  }

  // Half-closes, then reads and discards what the client still sends for a short while, so
  // that data arriving after our last response does not make the kernel reset the connection
  // before the client has read that response.
  void lingeringClose() {
    beast::error_code ignored;
    stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
    stream_.expires_after(std::chrono::milliseconds(
        std::min<uint32_t>(2000, std::max<uint32_t>(100, options().header_timeout_ms))));
    drain();
  }

  void drain() {
    buffer_.consume(buffer_.size());
    stream_.async_read_some(buffer_.prepare(4096),
                            [self = shared_from_this()](beast::error_code ec, size_t bytes) {
                              if (ec) return self->close();
                              self->buffer_.commit(bytes);
                              self->drain();
                            });
  }

  TileServer::Impl& server_;
  beast::tcp_stream stream_;
  beast::flat_buffer buffer_;
  std::optional<http::request_parser<http::string_body>> parser_;
  detail::Response response_;
  std::optional<http::serializer<false, detail::PartsBody>> serializer_;  // of response_
  std::string peer_, method_, target_;
  detail::Endpoint endpoint_ = detail::Endpoint::kOther;
  Clock::time_point started_{};
  bool head_ = false;
  bool idle_ = false;            // waiting for the first byte of a request
  bool stop_requested_ = false;  // close after the response in progress
};

void TileServer::Impl::accept() {
  net::io_context& context = *contexts[next_context++ % contexts.size()];
  acceptor->async_accept(context, [this](beast::error_code ec, tcp::socket socket) {
    if (ec == net::error::operation_aborted || stopping.load()) return;
    if (ec) {
      // Out of descriptors and the like: try again shortly instead of spinning.
      metrics.recordError(detail::ServeError::kIo);
      accept_retry->expires_after(std::chrono::milliseconds(50));
      accept_retry->async_wait([this](beast::error_code wait_ec) {
        if (!wait_ec) accept();
      });
      return;
    }
    if (metrics.open() >= options.max_connections) {
      metrics.connectionRejected();
      beast::error_code ignored;
      socket.close(ignored);
    } else {
      // Responses leave in one write; Nagle's algorithm would only hold back the tail of a
      // large one behind a delayed ACK.
      beast::error_code ignored;
      socket.set_option(tcp::no_delay(true), ignored);
      std::make_shared<Connection>(*this, std::move(socket))->start();
    }
    accept();
  });
}

Result<std::unique_ptr<TileServer>> TileServer::start(const ServeOptions& options) {
  if (options.threads > 1024)
    return fail(ErrorCode::kInvalidArgument, "serve: at most 1024 threads");
  if (options.jpeg_quality < 1 || options.jpeg_quality > 100)
    return fail(ErrorCode::kInvalidArgument, "serve: JPEG quality is 1..100");
  if (options.max_ranges == 0)
    return fail(ErrorCode::kInvalidArgument, "serve: --max-ranges must be at least 1");
  TESSERA_ASSIGN_OR_RETURN(detail::Catalog catalog, detail::loadCatalog(options.paths));
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  std::shared_ptr<const detail::AccessRules> access;
  if (!options.access_file.empty()) {
    TESSERA_ASSIGN_OR_RETURN(access, detail::AccessRules::load(options.access_file));
  }
  impl->router = std::make_unique<detail::Router>(std::move(catalog), options, impl->metrics,
                                                  std::move(access));
  TESSERA_TRY(impl->access_log.open(options.access_log));

  beast::error_code ec;
  net::ip::address address = net::ip::make_address(options.bind_address, ec);
  if (ec)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("serve: \"{}\" is not an IP address", options.bind_address));
  const uint32_t threads =
      options.threads ? options.threads : std::max(1u, std::thread::hardware_concurrency());
  for (uint32_t i = 0; i < threads; ++i) {
    impl->contexts.push_back(std::make_unique<net::io_context>(1));
    impl->keep_running.push_back(net::make_work_guard(*impl->contexts.back()));
  }
  impl->acceptor = std::make_unique<tcp::acceptor>(*impl->contexts[0]);
  impl->accept_retry = std::make_unique<net::steady_timer>(*impl->contexts[0]);
  tcp::endpoint endpoint(address, options.port);
  const std::string where = fmt::format("{}:{}", options.bind_address, options.port);
  if (impl->acceptor->open(endpoint.protocol(), ec); ec)
    return fail(ErrorCode::kIo,
                fmt::format("serve: cannot open a socket for {}: {}", where, ec.message()));
  impl->acceptor->set_option(net::socket_base::reuse_address(true), ec);
  if (impl->acceptor->bind(endpoint, ec); ec)
    return fail(ErrorCode::kIo, fmt::format("serve: cannot bind {}: {}", where, ec.message()));
  if (impl->acceptor->listen(net::socket_base::max_listen_connections, ec); ec)
    return fail(ErrorCode::kIo, fmt::format("serve: cannot listen on {}: {}", where, ec.message()));
  impl->port = impl->acceptor->local_endpoint().port();
  impl->address = address.to_string();

  if (options.on_listening) options.on_listening(impl->address, impl->port);
  impl->accept();
  for (uint32_t i = 0; i < threads; ++i)
    impl->threads.emplace_back([context = impl->contexts[i].get()] { context->run(); });
  return std::unique_ptr<TileServer>(new TileServer(std::move(impl)));
}

TileServer::TileServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

TileServer::~TileServer() {
  stop();
}

uint16_t TileServer::port() const {
  return impl_->port;
}

std::string TileServer::address() const {
  return impl_->address;
}

std::vector<std::string> TileServer::archiveNames() const {
  std::vector<std::string> names;
  for (const auto& [name, served] : impl_->router->catalog()) names.push_back(name);
  return names;
}

ServeStats TileServer::stats() const {
  const detail::Metrics& m = impl_->metrics;
  const detail::TranscodeCache::Stats cache = impl_->router->cache().stats();
  ServeStats stats;
  stats.requests = m.requests();
  stats.responses_2xx = m.responsesOfClass(2);
  stats.responses_3xx = m.responsesOfClass(3);
  stats.responses_4xx = m.responsesOfClass(4);
  stats.responses_5xx = m.responsesOfClass(5);
  stats.body_bytes_sent = m.bodyBytes();
  stats.connections_accepted = m.accepted();
  stats.connections_rejected = m.rejected();
  stats.connections_open = m.open();
  stats.timeouts = m.errors(detail::ServeError::kTimeout);
  stats.parse_errors = m.errors(detail::ServeError::kParse);
  stats.transcode_cache_hits = cache.hits;
  stats.transcode_cache_misses = cache.misses;
  stats.transcode_cache_bytes = cache.bytes;
  stats.transcode_cache_entries = cache.entries;
  return stats;
}

void TileServer::stop(uint32_t grace_ms) {
  std::lock_guard stop_lock(impl_->stop_mutex);
  if (impl_->stopped) return;
  impl_->stopped = true;
  impl_->stopping = true;
  net::post(impl_->acceptor->get_executor(), [impl = impl_.get()] {
    beast::error_code ignored;
    impl->acceptor->close(ignored);
    impl->accept_retry->cancel();
  });
  auto signalAll = [&](bool force) {
    std::vector<std::shared_ptr<Connection>> live;
    {
      std::lock_guard lock(impl_->registry_mutex);
      for (auto& [raw, weak] : impl_->connections)
        if (auto connection = weak.lock()) live.push_back(std::move(connection));
    }
    for (auto& connection : live) connection->requestStop(force);
  };
  signalAll(false);
  {
    std::unique_lock lock(impl_->registry_mutex);
    impl_->registry_changed.wait_for(lock, std::chrono::milliseconds(grace_ms),
                                     [&] { return impl_->connections.empty(); });
  }
  signalAll(true);
  {
    std::unique_lock lock(impl_->registry_mutex);
    impl_->registry_changed.wait_for(lock, std::chrono::milliseconds(1000),
                                     [&] { return impl_->connections.empty(); });
  }
  for (auto& context : impl_->contexts) context->stop();
  for (std::thread& thread : impl_->threads) thread.join();
  impl_->threads.clear();
}

}  // namespace tessera
