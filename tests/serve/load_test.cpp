// `tessera serve` under many concurrent connections: a few hundred keep-alive clients, plain
// and TLS, all at once, every response checked against the archive's own bytes; and a server
// whose file descriptors run out refuses the connections past its limit cleanly and goes on
// serving the ones it holds. The throughput figures are bench/serve_bench.sh's business.
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <vector>

#include <boost/asio/connect.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/ssl/context.hpp>
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/core/tcp_stream.hpp>
#include <boost/beast/http/empty_body.hpp>
#include <boost/beast/http/read.hpp>
#include <boost/beast/http/string_body.hpp>
#include <boost/beast/http/write.hpp>
#include <boost/beast/ssl/ssl_stream.hpp>
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <tessera/archive.h>

#include "serve/serve_fixture.h"
#include "serve/test_certificate.h"
#include "support/sanitizers.h"

namespace tessera::test {
namespace {

namespace net = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace ssl = net::ssl;
using tcp = net::ip::tcp;

constexpr int kConnections = 300;
constexpr int kRequestsPerConnection = 3;

struct Expected {
  std::string target;
  std::string payload;
};

// Every encoded tile of the archive, read through the library: what the server must send.
std::vector<Expected> expectedTiles(const std::string& path) {
  std::shared_ptr<Archive> archive = Archive::openFile(path).value();
  std::vector<Expected> tiles;
  const ImageInfo& info = archive->images()[0];
  for (uint32_t level = 0; level < info.level_count; ++level)
    for (uint32_t y = 0; y < info.tilesY(level); ++y)
      for (uint32_t x = 0; x < info.tilesX(level); ++x) {
        const TileId id{0, level, x, y};
        const TileEntry entry = archive->tileEntry(id).value();
        if (!entry.hasPayload()) continue;
        const std::vector<uint8_t> bytes = archive->readPayload(id, entry).value();
        tiles.push_back({fmt::format("/load/0/{}/{}/{}", level, x, y),
                         std::string(bytes.begin(), bytes.end())});
      }
  return tiles;
}

struct Tally {
  int correct = 0;
  int wrong = 0;
  std::vector<std::string> failures;  // the first few, for the message
  void fail(std::string why) {
    ++wrong;
    if (failures.size() < 5) failures.push_back(std::move(why));
  }
};

// One client connection: connect (and handshake), then kRequestsPerConnection requests on
// the kept-alive connection, each checked against the archive's bytes.
template <class Stream>
class Client : public std::enable_shared_from_this<Client<Stream>> {
 public:
  Client(std::unique_ptr<Stream> stream, const std::vector<Expected>& tiles, size_t first,
         Tally& tally)
      : stream_(std::move(stream)), tiles_(tiles), next_(first), tally_(tally) {}

  void start(const tcp::endpoint& server) {
    beast::get_lowest_layer(*stream_).expires_after(std::chrono::seconds(20));
    beast::get_lowest_layer(*stream_).async_connect(
        server, [self = this->shared_from_this()](beast::error_code ec) {
          if (ec) return self->tally_.fail("connect: " + ec.message());
          if constexpr (std::is_same_v<Stream, beast::tcp_stream>) {
            self->request();
          } else {
            self->stream_->async_handshake(
                ssl::stream_base::client, [self](beast::error_code handshake_ec) {
                  if (handshake_ec)
                    return self->tally_.fail("handshake: " + handshake_ec.message());
                  self->request();
                });
          }
        });
  }

 private:
  void request() {
    const Expected& tile = tiles_[next_ % tiles_.size()];
    request_ = {http::verb::get, tile.target, 11};
    request_.set(http::field::host, "127.0.0.1");
    beast::get_lowest_layer(*stream_).expires_after(std::chrono::seconds(20));
    http::async_write(
        *stream_, request_, [self = this->shared_from_this()](beast::error_code ec, size_t) {
          if (ec) return self->tally_.fail("write: " + ec.message());
          self->response_.emplace();
          http::async_read(
              *self->stream_, self->buffer_, *self->response_,
              [self](beast::error_code read_ec, size_t) { self->onResponse(read_ec); });
        });
  }

  void onResponse(beast::error_code ec) {
    const Expected& tile = tiles_[next_ % tiles_.size()];
    if (ec) return tally_.fail(tile.target + ": read: " + ec.message());
    if (response_->result_int() != 200 || response_->body() != tile.payload)
      tally_.fail(fmt::format("{}: status {}, {} bytes instead of {}", tile.target,
                              response_->result_int(), response_->body().size(),
                              tile.payload.size()));
    else
      ++tally_.correct;
    ++next_;
    if (++done_ < kRequestsPerConnection) return request();
    beast::error_code ignored;
    beast::get_lowest_layer(*stream_).socket().shutdown(tcp::socket::shutdown_both, ignored);
  }

  std::unique_ptr<Stream> stream_;
  const std::vector<Expected>& tiles_;
  size_t next_;
  Tally& tally_;
  int done_ = 0;
  http::request<http::empty_body> request_;
  beast::flat_buffer buffer_;
  std::optional<http::response<http::string_body>> response_;
};

// Runs kConnections clients at once, all on one thread; returns their tally.
Tally runClients(uint16_t port, const std::vector<Expected>& tiles, bool tls) {
  net::io_context context;
  ssl::context client_tls(ssl::context::tls_client);
  client_tls.set_verify_mode(ssl::verify_none);
  const tcp::endpoint server(net::ip::make_address("127.0.0.1"), port);
  Tally tally;
  for (int i = 0; i < kConnections; ++i) {
    const size_t first = size_t(i) * kRequestsPerConnection;
    if (tls)
      std::make_shared<Client<beast::ssl_stream<beast::tcp_stream>>>(
          std::make_unique<beast::ssl_stream<beast::tcp_stream>>(context, client_tls), tiles, first,
          tally)
          ->start(server);
    else
      std::make_shared<Client<beast::tcp_stream>>(std::make_unique<beast::tcp_stream>(context),
                                                  tiles, first, tally)
          ->start(server);
  }
  context.run();
  return tally;
}

class ServeLoad : public ::testing::Test {
 protected:
  void SetUp() override {
    path_ = servedArchive("load", 1024, 768, 3, Codec::kJpeg, 128, 0);
    ASSERT_FALSE(path_.empty());
    tiles_ = expectedTiles(path_);
    ASSERT_GT(tiles_.size(), 20u);
  }
  std::string path_;
  std::vector<Expected> tiles_;
};

void expectAllCorrect(const Tally& tally) {
  EXPECT_EQ(tally.wrong, 0) << fmt::format("{}", fmt::join(tally.failures, "; "));
  EXPECT_EQ(tally.correct, kConnections * kRequestsPerConnection);
}

TEST_F(ServeLoad, HundredsOfConcurrentPlainConnectionsAllGetTheRightBytes) {
  ServeOptions options;
  options.threads = 2;
  std::unique_ptr<TileServer> server = startServer({path_}, options);
  ASSERT_TRUE(server);
  expectAllCorrect(runClients(server->port(), tiles_, /*tls=*/false));
  EXPECT_GE(server->stats().connections_accepted, uint64_t(kConnections));
  EXPECT_EQ(server->stats().connections_rejected, 0u);
  EXPECT_EQ(httpRequest(server->port(), "/healthz").status, 200u);
}

TEST_F(ServeLoad, HundredsOfConcurrentTlsConnectionsAllGetTheRightBytes) {
  const std::string folder = std::filesystem::path(path_).parent_path().string();
  const PemPair pem = makeSelfSigned(7);
  ServeOptions options;
  options.threads = 2;
  options.tls_cert_file = folder + "/load-cert.pem";
  options.tls_key_file = folder + "/load-key.pem";
  std::ofstream(options.tls_cert_file) << pem.cert;
  std::ofstream(options.tls_key_file) << pem.key;
  std::unique_ptr<TileServer> server = startServer({path_}, options);
  ASSERT_TRUE(server);
  ASSERT_TRUE(server->tls());
  expectAllCorrect(runClients(server->port(), tiles_, /*tls=*/true));
  EXPECT_EQ(server->stats().tls_handshake_errors, 0u);
}

// What a forked server reports back: its port, then (after the parent says stop) how many
// connections it refused.
struct ChildServer {
  pid_t pid = -1;
  int to_child = -1, from_child = -1;
};

size_t openDescriptors() {
  size_t count = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator("/proc/self/fd"))
    ++count;
  return count;
}

// The server runs in a child process whose descriptor limit (soft and hard, so the server
// cannot raise it) leaves room for about 40 connections; the parent's own sockets do not
// count against it. The child is single-threaded when forked (no server runs in the parent).
ChildServer forkServerWithFewDescriptors(const std::string& path) {
  int to_child[2], from_child[2];
  if (::pipe(to_child) != 0 || ::pipe(from_child) != 0) return {};
  const pid_t pid = ::fork();
  if (pid != 0) {
    ::close(to_child[0]);
    ::close(from_child[1]);
    return {pid, to_child[1], from_child[0]};
  }
  ::close(to_child[1]);
  ::close(from_child[0]);
  const rlimit limit{openDescriptors() + 48, openDescriptors() + 48};
  if (::setrlimit(RLIMIT_NOFILE, &limit) != 0) ::_exit(3);
  ServeOptions options;
  options.paths = {path};
  options.threads = 1;
  Result<std::unique_ptr<TileServer>> server = TileServer::start(options);
  if (!server) ::_exit(4);
  const uint16_t port = (*server)->port();
  if (::write(from_child[1], &port, sizeof port) != sizeof port) ::_exit(5);
  char stop = 0;
  if (::read(to_child[0], &stop, 1) < 0) ::_exit(6);
  const uint64_t rejected = (*server)->stats().connections_rejected;
  (*server)->stop();
  if (::write(from_child[1], &rejected, sizeof rejected) != sizeof rejected) ::_exit(7);
  ::_exit(0);
}

TEST_F(ServeLoad, ClientsPastTheDescriptorLimitAreRefusedAndTheServerKeepsServing) {
  // UBSan's vptr check probes memory through a pipe: in a process at its descriptor limit it
  // reports valid objects as having an invalid vptr.
  if (test::sanitized())
    GTEST_SKIP() << "the sanitizer runtime misreports in a process without free descriptors";
  // A child that died must fail the test, not kill it with SIGPIPE on the control pipe.
  ::signal(SIGPIPE, SIG_IGN);
  ChildServer child = forkServerWithFewDescriptors(path_);
  ASSERT_GT(child.pid, 0);
  uint16_t port = 0;
  ASSERT_EQ(::read(child.from_child, &port, sizeof port), ssize_t(sizeof port));

  // 120 connections at once, three times what the child can hold: each either gets its tile
  // or is refused (503 or closed), and none hangs (RawConnection's reads time out in 10 s).
  std::vector<std::unique_ptr<RawConnection>> connections;
  for (int i = 0; i < 120; ++i) {
    connections.push_back(std::make_unique<RawConnection>(port));
    ASSERT_TRUE(connections.back()->connected());
  }
  const std::string request = fmt::format("GET {} HTTP/1.1\r\nHost: x\r\n\r\n", tiles_[0].target);
  int served = 0, refused = 0;
  // Refused means at once: a server that left them in its backlog would run into each
  // read's 10 s guard.
  const auto started = std::chrono::steady_clock::now();
  for (auto& connection : connections) {
    connection->send(request);  // a refused one may be closed already
    const std::string reply = connection->readOneResponse();
    if (statusOf(reply) == 200) {
      EXPECT_TRUE(reply.ends_with(tiles_[0].payload));
      ++served;
    } else {
      EXPECT_TRUE(reply.empty() || statusOf(reply) == 503) << reply.substr(0, 200);
      ++refused;
    }
  }
  EXPECT_LT(std::chrono::steady_clock::now() - started, std::chrono::seconds(5));
  EXPECT_GT(served, 10);
  EXPECT_GT(refused, 10);
  // A connection the server holds goes on being served on the same socket...
  int reused = 0;
  for (auto& connection : connections)
    if (connection->send(request) && statusOf(connection->readOneResponse()) == 200) ++reused;
  EXPECT_EQ(reused, served);
  // ...and once clients leave, new ones are served again.
  connections.clear();
  EXPECT_TRUE(eventually([&] {
    RawConnection fresh(port);
    return fresh.send(request) && statusOf(fresh.readOneResponse()) == 200;
  }));

  ASSERT_EQ(::write(child.to_child, "s", 1), 1);
  uint64_t rejected = 0;
  EXPECT_EQ(::read(child.from_child, &rejected, sizeof rejected), ssize_t(sizeof rejected));
  EXPECT_GE(rejected, uint64_t(refused));
  int status = 0;
  ASSERT_EQ(::waitpid(child.pid, &status, 0), child.pid);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "child status " << status;
  ::close(child.to_child);
  ::close(child.from_child);
}

}  // namespace
}  // namespace tessera::test
