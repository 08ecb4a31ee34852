// TileServer: the accept loop and one Connection per socket (connection.h), over Boost.Beast
// and Asio. Each connection lives on one I/O thread's io_context; request handling (pread,
// decode, encode) runs there too, which is cheap for stored tiles and bounded for transcodes
// by the cache.
#include <tessera/serve.h>

#include <fcntl.h>
#include <pthread.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>

#include <boost/asio/dispatch.hpp>
#include <boost/asio/post.hpp>
#include <fmt/format.h>

#include "connection.h"
#include "server_impl.h"
#include "tls_context.h"

namespace tessera {

namespace {

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

}  // namespace

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
