#pragma once
// The server's TLS stream: OpenSSL reads and writes the socket's descriptor itself and the
// connection waits for the socket's readiness between tries, the way nginx drives OpenSSL.
// Asio's ssl::stream passes every record through a memory BIO pair instead (two more copies
// of each response) and posts a completion for each step of each read and write; for small
// responses that machinery cost as much as the cryptography.
//
// An AsyncStream for Beast, with the handshake and shutdown of ssl::stream. Owned by one
// thread: the connection's I/O thread, which runs every handler.

#include <openssl/err.h>
#include <openssl/ssl.h>

#include <cerrno>
#include <cstddef>
#include <utility>

#include <boost/asio/buffer.hpp>
#include <boost/asio/compose.hpp>
#include <boost/asio/error.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/ssl/context.hpp>
#include <boost/asio/ssl/error.hpp>
#include <boost/asio/ssl/stream_base.hpp>
#include <boost/system/error_code.hpp>

namespace tessera::detail {

class TlsSocketStream {
 public:
  using socket_type = boost::asio::ip::tcp::socket;
  using executor_type = socket_type::executor_type;
  using error_code = boost::system::error_code;

  /// Takes the accepted socket; `context` is read here only (SSL_new keeps its own reference).
  TlsSocketStream(socket_type socket, boost::asio::ssl::context& context)
      : socket_(std::move(socket)), ssl_(SSL_new(context.native_handle())) {
    error_code ignored;
    socket_.non_blocking(true, ignored);  // OpenSSL's reads and writes must not block
    if (!ssl_) return;                    // every operation then fails (out of memory)
    SSL_set_fd(ssl_, int(socket_.native_handle()));
    SSL_set_accept_state(ssl_);
    // A write may finish after any whole record and be retried with the rest, which is what
    // write_some means; Beast may retry from a different buffer address. The record buffers
    // (about 34 KiB) go back to the allocator whenever they empty, as nginx has them: with a
    // thousand keep-alive connections, keeping them costs more in cache misses than the
    // allocations do.
    SSL_set_mode(ssl_, SSL_MODE_ENABLE_PARTIAL_WRITE | SSL_MODE_ACCEPT_MOVING_WRITE_BUFFER |
                           SSL_MODE_RELEASE_BUFFERS);
  }
  ~TlsSocketStream() {
    if (ssl_) SSL_free(ssl_);
  }
  TlsSocketStream(const TlsSocketStream&) = delete;
  TlsSocketStream& operator=(const TlsSocketStream&) = delete;

  executor_type get_executor() noexcept { return socket_.get_executor(); }
  socket_type& next_layer() { return socket_; }
  const socket_type& next_layer() const { return socket_; }
  SSL* native_handle() { return ssl_; }

  template <class Handler>
  auto async_handshake(boost::asio::ssl::stream_base::handshake_type, Handler&& handler) {
    return boost::asio::async_compose<Handler, void(error_code)>(
        Step<HandshakeCall, true>{*this, {}}, handler, socket_);
  }

  /// Sends close_notify and waits for the peer's.
  template <class Handler>
  auto async_shutdown(Handler&& handler) {
    return boost::asio::async_compose<Handler, void(error_code)>(
        Step<ShutdownCall, true>{*this, {}}, handler, socket_);
  }

  template <class MutableBuffers, class Handler>
  auto async_read_some(const MutableBuffers& buffers, Handler&& handler) {
    return boost::asio::async_compose<Handler, void(error_code, std::size_t)>(
        Step<ReadCall<MutableBuffers>, false>{*this, {buffers}}, handler, socket_);
  }

  template <class ConstBuffers, class Handler>
  auto async_write_some(const ConstBuffers& buffers, Handler&& handler) {
    return boost::asio::async_compose<Handler, void(error_code, std::size_t)>(
        Step<WriteCall<ConstBuffers>, false>{*this, {buffers}}, handler, socket_);
  }

 private:
  enum class Want { kDone, kRead, kWrite };

  // One try of an OpenSSL call: kDone with `ec` and `bytes` set, or what to wait for first.
  Want attempt(int result, error_code& ec) {
    if (result > 0) return Want::kDone;
    const int reason = SSL_get_error(ssl_, result);
    if (reason == SSL_ERROR_WANT_READ) return Want::kRead;
    if (reason == SSL_ERROR_WANT_WRITE) return Want::kWrite;
    if (reason == SSL_ERROR_ZERO_RETURN) {
      ec = boost::asio::error::eof;  // the peer's close_notify, as ssl::stream reports it
    } else if (reason == SSL_ERROR_SYSCALL && errno != 0 && ERR_peek_error() == 0) {
      ec = error_code(errno, boost::system::system_category());
    } else if (reason == SSL_ERROR_SYSCALL ||
               ERR_GET_REASON(ERR_peek_error()) == SSL_R_UNEXPECTED_EOF_WHILE_READING) {
      ec = boost::asio::ssl::error::stream_truncated;  // TCP closed without close_notify
    } else {
      ec = error_code(int(ERR_peek_error()), boost::asio::error::get_ssl_category());
    }
    ERR_clear_error();
    return Want::kDone;
  }

  struct HandshakeCall {
    int operator()(SSL* ssl, std::size_t&) { return SSL_do_handshake(ssl); }
  };
  struct ShutdownCall {
    // 0: our close_notify is out, the peer's not yet in; calling again waits for it.
    int operator()(SSL* ssl, std::size_t&) {
      const int sent = SSL_shutdown(ssl);
      return sent == 0 ? SSL_shutdown(ssl) : sent;
    }
  };
  template <class MutableBuffers>
  struct ReadCall {
    MutableBuffers buffers;
    int operator()(SSL* ssl, std::size_t& bytes) {
      for (auto it = boost::asio::buffer_sequence_begin(buffers);
           it != boost::asio::buffer_sequence_end(buffers); ++it) {
        const boost::asio::mutable_buffer buffer = *it;
        if (buffer.size() > 0) return SSL_read_ex(ssl, buffer.data(), buffer.size(), &bytes);
      }
      return 1;  // nothing asked, nothing read
    }
  };
  template <class ConstBuffers>
  struct WriteCall {
    ConstBuffers buffers;
    int operator()(SSL* ssl, std::size_t& bytes) {
      for (auto it = boost::asio::buffer_sequence_begin(buffers);
           it != boost::asio::buffer_sequence_end(buffers); ++it) {
        const boost::asio::const_buffer buffer = *it;
        if (buffer.size() > 0) return SSL_write_ex(ssl, buffer.data(), buffer.size(), &bytes);
      }
      return 1;
    }
  };

  // The composed operation: try the call; when OpenSSL needs the socket readable or writable,
  // wait for that and try again. A result available at once is delivered through the
  // executor, never from inside the initiating call (Asio's rule, which Beast relies on).
  template <class Call, bool kNoBytes>
  struct Step {
    TlsSocketStream& stream;
    Call call;
    error_code result{};
    std::size_t bytes = 0;
    bool waited = false;
    bool finished = false;

    template <class Self>
    void operator()(Self& self, error_code ec = {}) {
      if (finished) return complete(self);
      if (!ec && (!stream.ssl_ || !stream.socket_.is_open()))
        ec = boost::asio::error::bad_descriptor;  // never touch a descriptor closed under us
      if (ec) {
        result = ec;
        return complete(self);
      }
      ERR_clear_error();  // SSL_get_error reads the queue and errno: both must be fresh
      errno = 0;
      const int outcome = call(stream.ssl_, bytes);
      switch (stream.attempt(outcome, result)) {
        case Want::kRead:
          waited = true;
          return stream.socket_.async_wait(socket_type::wait_read, std::move(self));
        case Want::kWrite:
          waited = true;
          return stream.socket_.async_wait(socket_type::wait_write, std::move(self));
        case Want::kDone: break;
      }
      if (result) bytes = 0;
      finished = true;
      if (waited) return complete(self);
      boost::asio::post(stream.socket_.get_executor(), std::move(self));
    }

    template <class Self>
    void complete(Self& self) {
      if constexpr (kNoBytes)
        self.complete(result);
      else
        self.complete(result, bytes);
    }
  };

  socket_type socket_;
  SSL* ssl_;  // owned; reads and writes socket_'s descriptor
};

}  // namespace tessera::detail
