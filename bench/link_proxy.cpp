// tessera-link-proxy: a TCP proxy that behaves like a slow network link (a bandwidth and a
// round-trip time shared by every connection through it), for the remote-streaming benchmark
// (bench/link_bench.sh).
//
// Why a proxy and not netem: the issue asks for netem inside a network namespace, and this
// kernel has no sch_netem (`tc qdisc add ... netem` answers "Specified qdisc kind is
// unknown"; tbf and htb exist but add no delay). A proxy in user space gives every client
// (tessera fly, Chromium) the same link: bytes in each direction leave a FIFO queue at the
// link rate, one serialisation at a time across all connections as on one bottleneck, and
// arrive half the RTT later. Each connection may queue a bounded number of bytes before the
// proxy stops reading from it, which is what a TCP window does; the queue is the router's.
//
// Usage: tessera-link-proxy --listen 127.0.0.1:0 --upstream 127.0.0.1:8080 --rate 20mbit
//                           --rtt 40ms [--window-kib N]
// Prints "listening on 127.0.0.1:PORT" first, then on SIGINT/SIGTERM the bytes carried.
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <boost/asio.hpp>
#include <CLI/CLI.hpp>
#include <fmt/core.h>

namespace asio = boost::asio;
using asio::ip::tcp;
using Clock = std::chrono::steady_clock;
using asio::awaitable;
using asio::use_awaitable;

namespace {

// One direction of the link: a single serialiser shared by every connection, so two
// downloads at once each get half the rate, as on a real bottleneck.
struct LinkDirection {
  double bytes_per_s = 0;
  Clock::duration one_way_delay{};
  Clock::time_point free_at{};
  uint64_t bytes_carried = 0;

  // When `bytes` read now arrive at the far end.
  Clock::time_point arrivalOf(size_t bytes) {
    const Clock::time_point now = Clock::now();
    const auto serialise = std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(double(bytes) / bytes_per_s));
    free_at = std::max(now, free_at) + serialise;
    bytes_carried += bytes;
    return free_at + one_way_delay;
  }
};

// A wake-up signal between the reading and writing halves of one pipe: a timer that never
// expires, cancelled to wake whoever waits on it.
struct Signal {
  explicit Signal(const asio::any_io_executor& executor)
      : timer(executor, Clock::time_point::max()) {}
  awaitable<void> wait() {
    boost::system::error_code cancelled;
    co_await timer.async_wait(asio::redirect_error(use_awaitable, cancelled));
  }
  void notify() { timer.cancel(); }
  asio::steady_timer timer;
};

struct Chunk {
  std::vector<uint8_t> bytes;
  Clock::time_point arrival;
};

// Bytes of one connection in one direction, between being read from `from` and written to `to`.
struct Pipe {
  Pipe(const asio::any_io_executor& executor, size_t window)
      : readable(executor), writable(executor), delay(executor), window_bytes(window) {}
  std::deque<Chunk> queue;
  size_t queued_bytes = 0;
  bool source_done = false;
  Signal readable;  // the writer waits here for chunks
  Signal writable;  // the reader waits here for room in the window
  asio::steady_timer delay;
  size_t window_bytes;
  bool broken = false;  // the far end failed a write: this direction carries nothing more
};

awaitable<void> readSide(tcp::socket& from, Pipe& pipe, LinkDirection& link) {
  std::vector<uint8_t> buffer(16 * 1024);
  for (;;) {
    while (pipe.queued_bytes >= pipe.window_bytes && !pipe.broken) co_await pipe.writable.wait();
    if (pipe.broken) break;
    boost::system::error_code error;
    const size_t n = co_await from.async_read_some(asio::buffer(buffer),
                                                   asio::redirect_error(use_awaitable, error));
    if (error || n == 0) break;
    pipe.queue.push_back({{buffer.begin(), buffer.begin() + std::ptrdiff_t(n)}, link.arrivalOf(n)});
    pipe.queued_bytes += n;
    pipe.readable.notify();
  }
  pipe.source_done = true;
  pipe.readable.notify();
}

awaitable<void> writeSide(tcp::socket& to, tcp::socket& from, Pipe& pipe) {
  for (;;) {
    while (pipe.queue.empty() && !pipe.source_done) co_await pipe.readable.wait();
    if (pipe.queue.empty()) break;
    Chunk& chunk = pipe.queue.front();
    pipe.delay.expires_at(chunk.arrival);
    boost::system::error_code error;
    co_await pipe.delay.async_wait(asio::redirect_error(use_awaitable, error));
    error = {};
    co_await asio::async_write(to, asio::buffer(chunk.bytes),
                               asio::redirect_error(use_awaitable, error));
    if (error) {
      // The far end is gone: stop reading this direction too; closing `from` ends its read.
      pipe.broken = true;
      pipe.queue.clear();
      pipe.queued_bytes = 0;
      boost::system::error_code ignored;
      from.shutdown(tcp::socket::shutdown_receive, ignored);
      pipe.writable.notify();
      co_return;
    }
    pipe.queued_bytes -= chunk.bytes.size();
    pipe.queue.pop_front();
    pipe.writable.notify();
  }
  boost::system::error_code ignored;
  to.shutdown(tcp::socket::shutdown_send, ignored);
}

struct Proxy {
  tcp::endpoint upstream;
  LinkDirection to_server;
  LinkDirection to_client;
  size_t window_bytes = 0;
  uint64_t connections = 0;
};

awaitable<void> serveConnection(tcp::socket client, Proxy& proxy) {
  const auto executor = co_await asio::this_coro::executor;
  tcp::socket server(executor);
  boost::system::error_code error;
  co_await server.async_connect(proxy.upstream, asio::redirect_error(use_awaitable, error));
  if (error) co_return;
  client.set_option(tcp::no_delay(true));
  server.set_option(tcp::no_delay(true));
  ++proxy.connections;
  // A real connection costs a round trip (SYN, SYN-ACK) before the first request can leave;
  // the local connect above did not, so the bytes wait for it here.
  asio::steady_timer handshake(executor, proxy.to_server.one_way_delay * 2);
  co_await handshake.async_wait(asio::redirect_error(use_awaitable, error));
  auto up = std::make_shared<Pipe>(executor, proxy.window_bytes);
  auto down = std::make_shared<Pipe>(executor, proxy.window_bytes);
  auto client_socket = std::make_shared<tcp::socket>(std::move(client));
  auto server_socket = std::make_shared<tcp::socket>(std::move(server));
  // Four halves; the shared pointers keep sockets and pipes alive until the last one ends.
  auto keep = [=](auto) { (void)up, (void)down, (void)client_socket, (void)server_socket; };
  asio::co_spawn(executor, readSide(*client_socket, *up, proxy.to_server), keep);
  asio::co_spawn(executor, writeSide(*server_socket, *client_socket, *up), keep);
  asio::co_spawn(executor, readSide(*server_socket, *down, proxy.to_client), keep);
  asio::co_spawn(executor, writeSide(*client_socket, *server_socket, *down), keep);
}

awaitable<void> acceptLoop(tcp::acceptor& acceptor, Proxy& proxy) {
  for (;;) {
    boost::system::error_code error;
    tcp::socket socket = co_await acceptor.async_accept(asio::redirect_error(use_awaitable, error));
    if (error) co_return;
    asio::co_spawn(acceptor.get_executor(), serveConnection(std::move(socket), proxy),
                   asio::detached);
  }
}

std::optional<double> parseRateBitsPerS(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(), ::tolower);
  double scale = 1;
  for (auto [suffix, factor] :
       {std::pair{"gbit", 1e9}, {"mbit", 1e6}, {"kbit", 1e3}, {"bit", 1.0}}) {
    const std::string s = suffix;
    if (text.size() > s.size() && text.ends_with(s)) {
      scale = factor;
      text.resize(text.size() - s.size());
      break;
    }
  }
  try {
    size_t used = 0;
    const double value = std::stod(text, &used);
    if (used != text.size() || !(value > 0)) return std::nullopt;
    return value * scale;
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

std::optional<Clock::duration> parseMilliseconds(std::string text) {
  if (text.ends_with("ms")) text.resize(text.size() - 2);
  try {
    size_t used = 0;
    const double value = std::stod(text, &used);
    if (used != text.size() || value < 0) return std::nullopt;
    return std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double, std::milli>(value));
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

std::optional<tcp::endpoint> parseEndpoint(const std::string& text) {
  const size_t colon = text.rfind(':');
  if (colon == std::string::npos) return std::nullopt;
  boost::system::error_code error;
  const auto address = asio::ip::make_address(text.substr(0, colon), error);
  if (error) return std::nullopt;
  try {
    const int port = std::stoi(text.substr(colon + 1));
    if (port < 0 || port > 65535) return std::nullopt;
    return tcp::endpoint(address, uint16_t(port));
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"TCP proxy that behaves like a link of a given rate and round-trip time"};
  std::string listen_text = "127.0.0.1:0", upstream_text, rate_text, rtt_text;
  size_t window_kib = 0;
  app.add_option("--listen", listen_text, "address:port to listen on (port 0: any free one)");
  app.add_option("--upstream", upstream_text, "address:port of the server")->required();
  app.add_option("--rate", rate_text, "link rate per direction, e.g. 20mbit")->required();
  app.add_option("--rtt", rtt_text, "round-trip time, e.g. 40ms")->required();
  app.add_option("--window-kib", window_kib,
                 "bytes a connection may have queued per direction (default: 2 x the "
                 "bandwidth-delay product, at least 64 KiB)");
  CLI11_PARSE(app, argc, argv);

  const auto listen = parseEndpoint(listen_text);
  const auto upstream = parseEndpoint(upstream_text);
  const auto rate = parseRateBitsPerS(rate_text);
  const auto rtt = parseMilliseconds(rtt_text);
  if (!listen || !upstream || !rate || !rtt) {
    fmt::print(stderr, "tessera-link-proxy: bad {}\n",
               !listen     ? "--listen " + listen_text
               : !upstream ? "--upstream " + upstream_text
               : !rate     ? "--rate " + rate_text + " (e.g. 20mbit)"
                           : "--rtt " + rtt_text + " (e.g. 40ms)");
    return 2;
  }

  Proxy proxy;
  proxy.upstream = *upstream;
  for (LinkDirection* link : {&proxy.to_server, &proxy.to_client}) {
    link->bytes_per_s = *rate / 8;
    link->one_way_delay = *rtt / 2;
  }
  const double bdp_bytes = *rate / 8 * std::chrono::duration<double>(*rtt).count();
  proxy.window_bytes =
      window_kib ? window_kib * 1024 : std::max<size_t>(64 * 1024, size_t(2 * bdp_bytes));

  asio::io_context io;
  tcp::acceptor acceptor(io);
  boost::system::error_code error;
  acceptor.open(listen->protocol(), error);
  if (!error) acceptor.set_option(tcp::acceptor::reuse_address(true), error);
  if (!error) acceptor.bind(*listen, error);
  if (!error) acceptor.listen(asio::socket_base::max_listen_connections, error);
  if (error) {
    fmt::print(stderr, "tessera-link-proxy: cannot listen on {}: {}\n", listen_text,
               error.message());
    return 1;
  }
  const tcp::endpoint bound = acceptor.local_endpoint();
  fmt::print("listening on {}:{}\n", bound.address().to_string(), bound.port());
  std::fflush(stdout);

  asio::signal_set signals(io, SIGINT, SIGTERM);
  signals.async_wait([&](auto, int) { io.stop(); });
  asio::co_spawn(io, acceptLoop(acceptor, proxy), asio::detached);
  io.run();
  fmt::print("carried {} B to the server and {} B to clients over {} connections\n",
             proxy.to_server.bytes_carried, proxy.to_client.bytes_carried, proxy.connections);
  return 0;
}
