#pragma once
// One connection of `tessera serve`, plain TCP or TLS (OpenSSL over the same socket,
// tls_socket_stream.h): only the handshake and the close differ. It lives on one I/O
// thread's io_context: reads a request, has the router answer it, writes the response, and
// waits for the next, every wait bounded by a deadline (docs/serve.md). Private to
// tile_server.cpp, which adopts accepted sockets as connections.

#include <algorithm>
#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <type_traits>
#include <vector>

#include <boost/asio/post.hpp>
#include <boost/asio/ssl/error.hpp>
#include <boost/asio/write.hpp>
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/core/stream_traits.hpp>
#include <boost/beast/core/string.hpp>
#include <boost/beast/http/error.hpp>
#include <boost/beast/http/read.hpp>
#include <boost/beast/http/serializer.hpp>
#include <boost/beast/http/write.hpp>
#include <fmt/format.h>

#include "server_impl.h"
#include "tls_socket_stream.h"

namespace tessera {

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

}  // namespace tessera
