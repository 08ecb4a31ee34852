// TileServer: the accept loop and one Connection per socket, over Boost.Beast and Asio. Each
// connection lives on one I/O thread's io_context; request handling (pread, decode, encode)
// runs there too, which is cheap for stored tiles and bounded for transcodes by the cache.
// One Connection template serves plain TCP and TLS (OpenSSL over the same socket,
// tls_socket_stream.h): only the handshake and the close differ.
#include <tessera/serve.h>

#include <fcntl.h>
#include <pthread.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <ctime>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <type_traits>
#include <unordered_map>
#include <vector>

#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/dispatch.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/ssl/context.hpp>
#include <boost/asio/ssl/error.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/write.hpp>
#include <boost/beast/core/stream_traits.hpp>
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/core/string.hpp>
#include <boost/beast/http/error.hpp>
#include <boost/beast/http/read.hpp>
#include <boost/beast/http/serializer.hpp>
#include <boost/beast/http/write.hpp>
#include <fmt/format.h>

#include "router.h"
#include "tls_context.h"
#include "tls_socket_stream.h"

namespace tessera {

namespace net = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace ssl = net::ssl;
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

// Every connection holds a descriptor, and the usual soft limit (1024) is far below what a
// busy server needs; the soft limit is raised to the hard one, which only the administrator
// can raise further. Returns the limit in force.
uint64_t raiseFileLimit() {
  rlimit limit{};
  if (::getrlimit(RLIMIT_NOFILE, &limit) != 0) return 0;
  if (limit.rlim_cur < limit.rlim_max) {
    rlimit raised = limit;
    raised.rlim_cur = limit.rlim_max;
    if (::setrlimit(RLIMIT_NOFILE, &raised) == 0) return uint64_t(raised.rlim_cur);
  }
  return uint64_t(limit.rlim_cur);
}

bool outOfDescriptors(const boost::system::error_code& ec) {
  return ec.category() == boost::system::system_category() &&
         (ec.value() == EMFILE || ec.value() == ENFILE);
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

// What the server needs of a connection of either kind, to stop it.
class ConnectionBase {
 public:
  virtual ~ConnectionBase() = default;
  /// From any thread: closes the connection if it is waiting for a request, otherwise after
  /// the response in progress. `force` closes it whatever it is doing.
  virtual void requestStop(bool force) = 0;
};

struct TileServer::Impl {
  ServeOptions options;
  detail::Metrics metrics;
  std::unique_ptr<detail::Router> router;
  AccessLog access_log;
  std::atomic<bool> stopping{false};
  std::mutex registry_mutex;  // guards connections; taken after no other lock
  std::condition_variable registry_changed;
  std::unordered_map<ConnectionBase*, std::weak_ptr<ConnectionBase>> connections;
  std::mutex tls_mutex;  // guards tls_context; taken after no other lock
  // The context new connections handshake with; null when serving plain HTTP. reloadTls swaps
  // it; each TLS connection holds the one it started with.
  std::shared_ptr<ssl::context> tls_context;
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
  uint64_t file_limit = 0;  // RLIMIT_NOFILE after raiseFileLimit
  // A descriptor held in reserve (on /dev/null): when the process runs out, it is released to
  // accept one waiting connection and close it, so clients over the limit are refused at once
  // instead of waiting in the backlog; then it is taken back. Used by the accept handler only.
  int reserve_fd = -1;
  bool out_of_descriptors = false;  // reported once per episode; accept handler only
  bool stopped = false;
  std::mutex stop_mutex;  // serialises stop()

  ~Impl() {
    if (reserve_fd >= 0) ::close(reserve_fd);
  }
  /// Most connections taken from the backlog in one turn of the accepting thread.
  static constexpr int kAcceptBatch = 64;
  void accept();
  /// Starts serving an accepted socket, or closes it when over --max-connections.
  void adopt(tcp::socket socket);
  /// On EMFILE/ENFILE: refuses one waiting connection through the reserve descriptor. False
  /// when there was no reserve to spend (the caller retries later).
  bool refuseOverFileLimit();
  std::shared_ptr<ssl::context> currentTls() {
    std::lock_guard lock(tls_mutex);
    return tls_context;
  }
};

// Bare sockets, not beast::tcp_stream: its only addition, per-operation timeouts, is done
// more cheaply by the connection's watchdog, and its layer costs every read and write a
// composed operation. TLS runs OpenSSL on the socket itself (tls_socket_stream.h).
using PlainStream = tcp::socket;
using TlsStream = detail::TlsSocketStream;

template <class Stream>
class Connection : public ConnectionBase, public std::enable_shared_from_this<Connection<Stream>> {
  static constexpr bool kTls = std::is_same_v<Stream, TlsStream>;

 public:
  /// `tls` is the context of a TLS connection (kept alive as long as the connection), null
  /// for a plain one.
  Connection(TileServer::Impl& server, tcp::socket socket, std::shared_ptr<ssl::context> tls)
      : server_(server),
        tls_(std::move(tls)),
        stream_(openStream(std::move(socket), tls_.get())),
        watchdog_(stream_.get_executor()) {
    beast::error_code ec;
    tcp::endpoint remote = tcpSocket().remote_endpoint(ec);
    peer_ = ec ? "-" : fmt::format("{}:{}", remote.address().to_string(), remote.port());
    // Plain writes are tried inline first (writeInline), and must fail with would_block
    // rather than wait when the send buffer is full.
    if constexpr (!kTls) tcpSocket().non_blocking(true, ec);
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
      server_.connections[this] = this->weak_from_this();
    }
    net::dispatch(stream_.get_executor(), [self = this->shared_from_this()] {
      if constexpr (kTls)
        self->handshake();
      else
        self->waitForRequest();
    });
  }

  void requestStop(bool force) override {
    net::post(stream_.get_executor(), [self = this->shared_from_this(), force] {
      self->stop_requested_ = true;
      if (force || self->idle_) {
        beast::error_code ignored;
        self->tcpSocket().close(ignored);
      }
    });
  }

 private:
  using Request = detail::Request;
  const ServeOptions& options() const { return server_.options; }
  tcp::socket& tcpSocket() { return beast::get_lowest_layer(stream_); }

  // Timeouts are deadlines checked by one timer per connection, not Beast's per-operation
  // timers (beast::tcp_stream::expires_after), which schedule and cancel a timer around every read
  // and write: a tenth of a small request's cost. The timer is re-armed only when it fires
  // before the deadline or a deadline moves earlier; on expiry it closes the socket, so the
  // operation in progress fails and timed_out_ says why.
  void expireAfter(std::chrono::milliseconds timeout) {
    deadline_ = Clock::now() + timeout;
    if (watchdog_armed_ && watchdog_.expiry() <= deadline_) return;
    armWatchdog();
  }

  // The handler holds the connection weakly, so that a pending wait (up to an idle timeout)
  // does not keep a closed connection alive; the timer's destruction cancels it.
  void armWatchdog() {
    watchdog_armed_ = true;
    watchdog_.expires_at(deadline_);
    watchdog_.async_wait([weak = this->weak_from_this()](beast::error_code ec) {
      if (ec) return;  // re-armed for an earlier deadline, or the connection is going
      if (auto self = weak.lock()) self->onWatchdog();
    });
  }

  void onWatchdog() {
    watchdog_armed_ = false;
    if (Clock::now() < deadline_) return armWatchdog();
    timed_out_ = true;
    close();
  }

  bool timedOut(beast::error_code ec) const { return timed_out_ || ec == beast::error::timeout; }

  static Stream openStream(tcp::socket socket, ssl::context* tls) {
    if constexpr (kTls)
      return Stream(std::move(socket), *tls);
    else
      return Stream(std::move(socket));
  }

  // The handshake runs under the header timeout: a client that connects and says nothing
  // costs no more than one that starts a request and stops.
  void handshake() {
    started_ = Clock::now();
    idle_ = true;
    expireAfter(std::chrono::milliseconds(options().header_timeout_ms));
    stream_.async_handshake(ssl::stream_base::server,
                            [self = this->shared_from_this()](beast::error_code ec) {
                              self->idle_ = false;
                              if (ec) return self->onHandshakeError(ec);
                              self->tls_established_ = true;
                              self->waitForRequest();
                            });
  }

  // Plain HTTP sent to the TLS port, a broken or foreign client hello, a timeout: counted,
  // logged (status 0, the cause as the target) and closed without a word, since there is no
  // TLS session to answer in.
  void onHandshakeError(beast::error_code ec) {
    const bool timeout = timedOut(ec);
    server_.metrics.recordError(timeout ? detail::ServeError::kTimeout : detail::ServeError::kTls);
    if (server_.access_log.enabled()) {
      std::string cause = timeout ? "timeout" : ec.message();
      for (char& c : cause)
        if (c == ' ') c = '_';
      const int64_t micros =
          std::chrono::duration_cast<std::chrono::microseconds>(Clock::now() - started_).count();
      server_.access_log.write(peer_, "TLS", "handshake:" + cause, 0, 0, micros);
    }
    tcpLingeringClose();
  }

  void waitForRequest() {
    if (stop_requested_) return close();
    // Bytes already buffered (a pipelined request) start the next request at once; otherwise
    // the idle timeout runs until its first byte arrives, then the header timeout.
    if (buffer_.size() > 0) return readHeader();
    idle_ = true;
    expireAfter(std::chrono::milliseconds(options().idle_timeout_ms));
    stream_.async_read_some(buffer_.prepare(4096),
                            [self = this->shared_from_this()](beast::error_code ec, size_t bytes) {
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
    // A header that arrived whole (the usual case: waitForRequest read it) is parsed here and
    // now; async_read_header would parse the same bytes after a trip through the queue. Of an
    // incomplete one the parser may already have taken the start line: async_read_header goes
    // on from there, and those bytes count towards the header's size.
    size_t parsed_bytes = 0;
    if (buffer_.size() > 0) {
      beast::error_code ec;
      parsed_bytes = parser_->put(buffer_.data(), ec);
      buffer_.consume(parsed_bytes);
      if (ec != http::error::need_more) return onHeader(ec, parsed_bytes);
    }
    expireAfter(std::chrono::milliseconds(options().header_timeout_ms));
    http::async_read_header(
        stream_, buffer_, *parser_,
        [self = this->shared_from_this(), parsed_bytes](beast::error_code ec, size_t bytes) {
          self->onHeader(ec, parsed_bytes + bytes);
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
      expireAfter(std::chrono::milliseconds(options().body_timeout_ms));
      http::async_read(stream_, buffer_, *parser_,
                       [self = this->shared_from_this()](beast::error_code read_ec, size_t) {
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
    // Kept for the access log line only: two allocations per request saved without one.
    if (server_.access_log.enabled()) {
      method_ = std::string(request.method_string());
      target_ = std::string(request.target());
    }
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
    if (!formatDirect()) {
      serializer_.emplace(response_);
      return writeSome();
    }
    expireAfter(std::chrono::milliseconds(options().send_timeout_ms));
    if constexpr (!kTls) {
      if (!writing_inline_ && writeInline()) return;
    }
    auto done = [self = this->shared_from_this()](beast::error_code ec, size_t) {
      self->onWritten(ec);
    };
    if constexpr (kTls)
      net::async_write(stream_, net::buffer(out_), std::move(done));
    else
      net::async_write(stream_, gather_, std::move(done));
  }

  // Most plain responses fit the socket's send buffer: sent here in one sendmsg, and the
  // connection goes on to its next request without a trip through the queue. What did not
  // fit is left in gather_ for the asynchronous write (false). Not for a write reached from
  // an inline one (pipelined requests), which would nest a call per request.
  bool writeInline() {
    beast::error_code ec;
    size_t sent = tcpSocket().write_some(gather_, ec);
    if (ec == net::error::would_block || ec == net::error::try_again) ec = {};
    size_t first = 0;
    while (first < gather_.size() && sent >= gather_[first].size()) sent -= gather_[first++].size();
    if (!ec && first < gather_.size()) {
      gather_.erase(gather_.begin(), gather_.begin() + std::ptrdiff_t(first));
      gather_.front() += sent;
      return false;
    }
    writing_inline_ = true;
    onWritten(ec);
    writing_inline_ = false;
    return true;
  }

  // Tiles, documents and errors (small bodies, all in memory) skip Beast's serializer, whose
  // buffer-sequence walks and per-write composed operations cost as much as the request:
  // the header is formatted into out_ and goes out with the body in one gather write, or
  // over TLS copied with the body into out_, so that it leaves as one TLS record instead of
  // two. False, with nothing written, for a response the serializer must stream (file
  // parts, large or many parts, chunked).
  bool formatDirect() {
    const std::vector<detail::BodyPart>& parts = response_.body();
    if (parts.size() > kDirectParts || response_.chunked()) return false;
    uint64_t body_bytes = 0;
    for (const detail::BodyPart& part : parts) {
      if (part.source) return false;
      body_bytes += part.memory.size();
    }
    if (body_bytes > kDirectBodyBytes) return false;
    // The bytes Beast's serializer writes: status line, fields as stored, blank line.
    const unsigned version = response_.version();
    const unsigned status = response_.result_int();
    char status_line[] = "HTTP/1.1 200 ";
    status_line[5] = char('0' + version / 10 % 10);
    status_line[7] = char('0' + version % 10);
    status_line[9] = char('0' + status / 100 % 10);
    status_line[10] = char('0' + status / 10 % 10);
    status_line[11] = char('0' + status % 10);
    out_.clear();
    out_.append(status_line, sizeof status_line - 1);
    out_.append(response_.reason());
    out_.append("\r\n");
    for (const auto& field : response_) {
      out_.append(field.name_string());
      out_.append(": ");
      out_.append(field.value());
      out_.append("\r\n");
    }
    out_.append("\r\n");
    if constexpr (kTls) {
      for (const detail::BodyPart& part : parts) out_.append(part.memory);
    } else {
      gather_.clear();
      gather_.push_back(net::buffer(out_));
      for (const detail::BodyPart& part : parts)
        gather_.push_back(net::buffer(part.memory.data(), part.memory.size()));
    }
    return true;
  }

  // The send timeout runs per write, not per response: a large archive download to a slow but
  // live client keeps going, while a client that stops reading is closed.
  void writeSome() {
    expireAfter(std::chrono::milliseconds(options().send_timeout_ms));
    http::async_write_some(stream_, *serializer_,
                           [self = this->shared_from_this()](beast::error_code ec, size_t) {
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
    gather_.clear();
    // The buffer is kept for the next response, unless a large one made it grow.
    if (out_.capacity() > kKeptOutBytes) out_ = std::string();
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
        ec == net::error::bad_descriptor || ec == ssl::error::stream_truncated)
      return onSocketError(ec);
    if (ec.category() == http::make_error_code(http::error::bad_method).category())
      return refuse(http::status::bad_request, fmt::format("malformed request: {}", ec.message()));
    onSocketError(ec);
  }

  void onSocketError(beast::error_code ec) {
    if (timedOut(ec)) {
      server_.metrics.recordError(detail::ServeError::kTimeout);
    } else if (ec != http::error::end_of_stream && ec != net::error::eof &&
               ec != net::error::operation_aborted && ec != net::error::connection_reset &&
               ec != net::error::bad_descriptor && ec != http::error::partial_message &&
               ec != ssl::error::stream_truncated) {
      server_.metrics.recordError(detail::ServeError::kIo);
    }
    close();
  }

  void close() {
    beast::error_code ignored;
    tcpSocket().close(ignored);
  }

  std::chrono::milliseconds closeBound() const {
    return std::chrono::milliseconds(
        std::min<uint32_t>(2000, std::max<uint32_t>(100, options().header_timeout_ms)));
  }

  // A TLS session ends with close_notify both ways (bounded: a client that never answers is
  // closed when the time runs out), then the TCP connection closes as a plain one does.
  void lingeringClose() {
    if constexpr (kTls) {
      if (tls_established_) {
        expireAfter(closeBound());
        stream_.async_shutdown(
            [self = this->shared_from_this()](beast::error_code) { self->tcpLingeringClose(); });
        return;
      }
    }
    tcpLingeringClose();
  }

  // Half-closes, then reads and discards what the client still sends for a short while, so
  // that data arriving after our last response does not make the kernel reset the connection
  // before the client has read that response.
  void tcpLingeringClose() {
    beast::error_code ignored;
    tcpSocket().shutdown(tcp::socket::shutdown_send, ignored);
    expireAfter(closeBound());
    drain();
  }

  // Raw TCP reads under TLS too: after close_notify, or a failed handshake, nothing left is
  // worth decrypting.
  void drain() {
    buffer_.consume(buffer_.size());
    tcpSocket().async_read_some(buffer_.prepare(4096), [self = this->shared_from_this()](
                                                           beast::error_code ec, size_t bytes) {
      if (ec) return self->close();
      self->buffer_.commit(bytes);
      self->drain();
    });
  }

  TileServer::Impl& server_;
  std::shared_ptr<ssl::context> tls_;  // before stream_, which refers to it
  Stream stream_;
  net::steady_timer watchdog_;  // fires at or before deadline_ while watchdog_armed_
  Clock::time_point deadline_ = Clock::time_point::max();  // of the operation in progress
  bool watchdog_armed_ = false;
  bool timed_out_ = false;  // the watchdog closed the socket: the error that follows is a timeout
  beast::flat_buffer buffer_;
  std::optional<http::request_parser<http::string_body>> parser_;
  detail::Response response_;
  std::optional<http::serializer<false, detail::PartsBody>> serializer_;  // of response_
  // Limits of the direct write (formatDirect): past them the serializer streams the body.
  static constexpr size_t kDirectParts = 8;
  static constexpr uint64_t kDirectBodyBytes = 64 * 1024;
  static constexpr size_t kKeptOutBytes = 32 * 1024;
  std::string out_;  // a direct write's header (plain) or whole response (TLS)
  std::vector<net::const_buffer> gather_;  // a plain direct write: out_, then the body parts
  std::string peer_, method_, target_;
  detail::Endpoint endpoint_ = detail::Endpoint::kOther;
  Clock::time_point started_{};
  bool head_ = false;
  bool tls_established_ = false;
  bool idle_ = false;            // waiting for the first byte of a request
  bool stop_requested_ = false;  // close after the response in progress
  bool writing_inline_ = false;  // inside writeInline's call of onWritten
};

void TileServer::Impl::adopt(tcp::socket socket) {
  out_of_descriptors = false;
  if (metrics.open() >= options.max_connections) {
    metrics.connectionRejected();
    beast::error_code ignored;
    socket.close(ignored);
    return;
  }
  // Responses leave in one write; Nagle's algorithm would only hold back the tail of a large
  // one behind a delayed ACK.
  beast::error_code ignored;
  socket.set_option(tcp::no_delay(true), ignored);
  if (std::shared_ptr<ssl::context> tls = currentTls())
    std::make_shared<Connection<TlsStream>>(*this, std::move(socket), std::move(tls))->start();
  else
    std::make_shared<Connection<PlainStream>>(*this, std::move(socket), nullptr)->start();
}

void TileServer::Impl::accept() {
  net::io_context& context = *contexts[next_context++ % contexts.size()];
  acceptor->async_accept(context, [this](beast::error_code ec, tcp::socket socket) {
    if (ec == net::error::operation_aborted || stopping.load()) return;
    if (!ec) {
      adopt(std::move(socket));
      // Connections come in bursts (a viewer opening, a thousand clients at once): the ones
      // already waiting are taken now, not one per turn of this thread's queue, where each
      // would wait behind the handlers of every open connection. The acceptor is
      // non-blocking, so the loop ends at would_block.
      for (int taken = 0; taken < kAcceptBatch && !ec; ++taken) {
        tcp::socket next(*contexts[next_context % contexts.size()]);
        if (acceptor->accept(next, ec); ec) break;
        ++next_context;
        adopt(std::move(next));
      }
      if (ec == net::error::would_block || ec == net::error::try_again) ec = {};
    }
    if (outOfDescriptors(ec) && refuseOverFileLimit()) return accept();
    if (ec) {
      // Out of descriptors without a reserve, and the like: try again shortly instead of
      // spinning.
      metrics.recordError(detail::ServeError::kIo);
      accept_retry->expires_after(std::chrono::milliseconds(50));
      accept_retry->async_wait([this](beast::error_code wait_ec) {
        if (!wait_ec) accept();
      });
      return;
    }
    accept();
  });
}

bool TileServer::Impl::refuseOverFileLimit() {
  if (!out_of_descriptors) {
    out_of_descriptors = true;
    std::fprintf(stderr,
                 "tessera serve: out of file descriptors (limit %llu, %llu connections open): "
                 "refusing new connections until some close; raise the hard limit (ulimit -Hn, "
                 "LimitNOFILE=) to serve more\n",
                 static_cast<unsigned long long>(file_limit),
                 static_cast<unsigned long long>(metrics.open()));
  }
  if (reserve_fd < 0) return false;
  ::close(reserve_fd);
  reserve_fd = -1;
  const int refused = ::accept4(acceptor->native_handle(), nullptr, nullptr, SOCK_CLOEXEC);
  if (refused >= 0) {
    metrics.connectionRejected();
    // Plain HTTP clients get a reason; a TLS client sees the connection closed. Best effort:
    // the socket is fresh, so a short send fits its buffer or is dropped.
    if (!currentTls()) {
      static constexpr std::string_view kBusy =
          "HTTP/1.1 503 Service Unavailable\r\nContent-Length: 0\r\nConnection: close\r\n"
          "Retry-After: 1\r\n\r\n";
      [[maybe_unused]] const ssize_t sent =
          ::send(refused, kBusy.data(), kBusy.size(), MSG_DONTWAIT | MSG_NOSIGNAL);
      ::shutdown(refused, SHUT_WR);
    }
    ::close(refused);
  }
  reserve_fd = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
  return refused >= 0 || errno == EAGAIN || errno == EWOULDBLOCK;
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
  impl->file_limit = raiseFileLimit();
  impl->reserve_fd = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
  // Past the limit connections are refused cleanly, but an operator should know beforehand
  // (a few descriptors go to the archives, the log and the I/O threads' event queues).
  if (impl->file_limit != 0 && impl->file_limit < uint64_t(options.max_connections) + 64)
    std::fprintf(stderr,
                 "tessera serve: the file descriptor limit (%llu) is below --max-connections "
                 "(%u) plus 64 spare: connections past it are refused\n",
                 static_cast<unsigned long long>(impl->file_limit), options.max_connections);
  std::shared_ptr<const detail::AccessRules> access;
  if (!options.access_file.empty()) {
    TESSERA_ASSIGN_OR_RETURN(access, detail::AccessRules::load(options.access_file));
  }
  impl->router = std::make_unique<detail::Router>(std::move(catalog), options, impl->metrics,
                                                  std::move(access));
  TESSERA_TRY(impl->access_log.open(options.access_log));
  if (!options.tls_cert_file.empty() || !options.tls_key_file.empty()) {
    TESSERA_ASSIGN_OR_RETURN(impl->tls_context, detail::makeServerTlsContext(options.tls_cert_file,
                                                                             options.tls_key_file));
  }

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
  // The accept handler's batch and refuseOverFileLimit accept synchronously, and must get
  // would_block instead of waiting when nobody is left in the backlog (asynchronous accepts
  // are unaffected).
  impl->acceptor->non_blocking(true, ec);
  impl->acceptor->native_non_blocking(true, ec);
  impl->port = impl->acceptor->local_endpoint().port();
  impl->address = address.to_string();

  if (options.on_listening) options.on_listening(impl->address, impl->port);
  impl->accept();
  for (uint32_t i = 0; i < threads; ++i)
    impl->threads.emplace_back([context = impl->contexts[i].get()] {
      // OpenSSL writes TLS records with write(), which raises SIGPIPE on a connection the
      // client has reset; blocked here, the write just fails with EPIPE.
      sigset_t pipe;
      sigemptyset(&pipe);
      sigaddset(&pipe, SIGPIPE);
      pthread_sigmask(SIG_BLOCK, &pipe, nullptr);
      context->run();
    });
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
  stats.tls_handshake_errors = m.errors(detail::ServeError::kTls);
  stats.transcode_cache_hits = cache.hits;
  stats.transcode_cache_misses = cache.misses;
  stats.transcode_cache_bytes = cache.bytes;
  stats.transcode_cache_entries = cache.entries;
  return stats;
}

bool TileServer::tls() const {
  return impl_->currentTls() != nullptr;
}

Result<void> TileServer::reloadTls() {
  if (!tls()) return fail(ErrorCode::kInvalidArgument, "serve: not serving TLS, nothing to reload");
  // Built outside the lock: loading files is slow next to an accept.
  TESSERA_ASSIGN_OR_RETURN(
      std::shared_ptr<ssl::context> fresh,
      detail::makeServerTlsContext(impl_->options.tls_cert_file, impl_->options.tls_key_file));
  std::lock_guard lock(impl_->tls_mutex);
  impl_->tls_context = std::move(fresh);
  return {};
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
    std::vector<std::shared_ptr<ConnectionBase>> live;
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
