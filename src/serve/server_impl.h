#pragma once
// TileServer's state shared by its accept loop (tile_server.cpp) and its connections
// (connection.h): options, metrics, the router, the registry of open connections, the TLS
// context and the I/O threads' io_contexts. Private to the serve module.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include <unistd.h>

#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/ssl/context.hpp>
#include <boost/asio/steady_timer.hpp>

#include <tessera/serve.h>

#include "access_log.h"
#include "metrics.h"
#include "router.h"

namespace tessera {

namespace net = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace ssl = net::ssl;
using tcp = net::ip::tcp;
using Clock = std::chrono::steady_clock;

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
  detail::AccessLog access_log;
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

}  // namespace tessera
