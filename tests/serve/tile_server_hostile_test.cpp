// Hostile input and load against an in-process server (issue 5, item 7): path traversal,
// malformed requests, oversized headers and bodies, smuggling patterns, range abuse, huge
// indexes, slow and idle clients, connection limits. Each case gets the status docs/serve.md
// gives it, and the server keeps serving other clients.
#include <chrono>
#include <thread>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <tessera/serve.h>

#include "serve/serve_fixture.h"

namespace tessera::test {
namespace {

std::string archivePath() {
  return servedArchive("hostile", 512, 384, 3, Codec::kPng, 128, 0);
}

class HostileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ServeOptions options;
    options.header_timeout_ms = 300;
    options.body_timeout_ms = 300;
    options.idle_timeout_ms = 300;
    options.send_timeout_ms = 300;
    options.header_limit_bytes = 4096;
    options.body_limit_bytes = 1024;
    options.max_ranges = 8;
    server_ = startServer({archivePath()}, options);
    ASSERT_NE(server_, nullptr);
    port_ = server_->port();
  }

  // Sends `bytes` on a fresh connection and returns everything the server sends before
  // closing; fails if the server does not close.
  std::string exchangeAndClose(const std::string& bytes) {
    RawConnection connection(port_);
    EXPECT_TRUE(connection.connected());
    connection.send(bytes);
    bool timed_out = false;
    std::string reply = connection.readUntilClosed(&timed_out);
    EXPECT_FALSE(timed_out) << "the server did not close the connection";
    return reply;
  }

  unsigned statusOfGet(const std::string& target) {
    RawConnection connection(port_);
    connection.send(fmt::format("GET {} HTTP/1.1\r\nHost: x\r\n\r\n", target));
    return statusOf(connection.readOneResponse());
  }

  void expectStillServing() {
    HttpReply reply = httpRequest(port_, "/hostile/0/0/0/0");
    EXPECT_EQ(reply.status, 200u);
  }

  std::unique_ptr<TileServer> server_;
  uint16_t port_ = 0;
};

TEST_F(HostileTest, PathTraversalIsRefused) {
  for (const char* target :
       {"/../etc/passwd", "/hostile/../hostile.tess", "/%2e%2e/etc/passwd",
        "/%2E%2E%2Fetc%2Fpasswd", "/viewer/..%2f..%2fetc%2fpasswd", "/viewer/%2e%2e/index.html",
        "/hostile%2finfo.json", "/hostile%5c..%5cinfo.json", "/hostile/%00/info.json", "/%zz",
        "/viewer/%"})
    EXPECT_EQ(statusOfGet(target), 400u) << target;
  // Not a path at all (absolute-form or asterisk-form) is refused too.
  EXPECT_EQ(statusOfGet("http://127.0.0.1/hostile.tess"), 400u);
  EXPECT_EQ(statusOfGet("*"), 400u);
  // Anything else that names no resource is simply not found; nothing maps to the disk.
  for (const char* target : {"//etc/passwd", "/etc/passwd", "/viewer/../../../../etc/passwd.tess",
                             "/hostile/info.json/", "/viewer//etc/passwd"})
    EXPECT_NE(statusOfGet(target), 200u) << target;
  EXPECT_EQ(statusOfGet("/%68ostile/info.json"), 200u);  // percent-encoded 'h' is just 'h'
  expectStillServing();
}

TEST_F(HostileTest, MalformedRequestLinesAndHeadersAre400AndClosed) {
  for (const char* request :
       {"GARBAGE\r\n\r\n", "GET\r\n\r\n", "GET / HTTP/9.9\r\n\r\n", "GET / FTP/1.1\r\n\r\n",
        "GET /\x01 HTTP/1.1\r\n\r\n", "GET / HTTP/1.1\r\nNo colon here\r\n\r\n",
        "GET / HTTP/1.1\r\n: empty name\r\n\r\n", "GET / HTTP/1.1\r\nBad Name: x\r\n\r\n",
        "\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03\r\n\r\n"}) {
    std::string reply = exchangeAndClose(request);
    EXPECT_EQ(statusOf(reply), 400u) << request;
  }
  EXPECT_TRUE(eventually([&] { return server_->stats().parse_errors >= 9; }));
  expectStillServing();
}

TEST_F(HostileTest, OversizedHeaderIs431AndClosed) {
  std::string request =
      "GET /healthz HTTP/1.1\r\nHost: x\r\nX-Big: " + std::string(8000, 'a') + "\r\n\r\n";
  EXPECT_EQ(statusOf(exchangeAndClose(request)), 431u);
  std::string many = "GET /healthz HTTP/1.1\r\n";
  for (int i = 0; i < 500; ++i) many += fmt::format("X-H{}: v\r\n", i);
  EXPECT_EQ(statusOf(exchangeAndClose(many + "\r\n")), 431u);
  std::string long_target = "GET /" + std::string(6000, 'a') + " HTTP/1.1\r\n\r\n";
  EXPECT_EQ(statusOf(exchangeAndClose(long_target)), 431u);
  expectStillServing();
}

TEST_F(HostileTest, OversizedBodyIs413) {
  std::string request =
      "GET /healthz HTTP/1.1\r\nHost: x\r\nContent-Length: 100000\r\n\r\n" + std::string(2000, 'b');
  EXPECT_EQ(statusOf(exchangeAndClose(request)), 413u);
  std::string chunked =
      "GET /healthz HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\n"
      "100000\r\n" +
      std::string(2000, 'c');
  EXPECT_EQ(statusOf(exchangeAndClose(chunked)), 413u);
  expectStillServing();
}

TEST_F(HostileTest, SmugglingPatternsAreRefused) {
  // CL.TE and TE.CL: both framings present.
  EXPECT_EQ(statusOf(exchangeAndClose("GET /healthz HTTP/1.1\r\nHost: x\r\nContent-Length: 4\r\n"
                                      "Transfer-Encoding: chunked\r\n\r\n0\r\n\r\n")),
            400u);
  EXPECT_EQ(statusOf(exchangeAndClose("GET /healthz HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: "
                                      "chunked\r\nContent-Length: 3\r\n\r\n0\r\n\r\n")),
            400u);
  // Two Content-Length values.
  EXPECT_EQ(statusOf(exchangeAndClose("GET /healthz HTTP/1.1\r\nHost: x\r\nContent-Length: 0\r\n"
                                      "Content-Length: 5\r\n\r\nhello")),
            400u);
  // Obfuscated or unknown transfer codings and a malformed length.
  EXPECT_EQ(statusOf(exchangeAndClose("GET /healthz HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: "
                                      "xchunked\r\n\r\n0\r\n\r\n")),
            501u);
  EXPECT_EQ(statusOf(exchangeAndClose("GET /healthz HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: "
                                      "gzip, chunked\r\n\r\n0\r\n\r\n")),
            501u);
  EXPECT_EQ(statusOf(exchangeAndClose("GET /healthz HTTP/1.1\r\nHost: x\r\nContent-Length: "
                                      "+5\r\n\r\nhello")),
            400u);
  EXPECT_EQ(statusOf(exchangeAndClose("GET /healthz HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: "
                                      "chunked\r\n\r\nzz\r\n\r\n")),
            400u);
  expectStillServing();
}

TEST_F(HostileTest, ABodyIsReadAndTheNextPipelinedRequestStillAnswered) {
  RawConnection connection(port_);
  connection.send(
      "GET /healthz HTTP/1.1\r\nHost: x\r\nContent-Length: 5\r\n\r\nhelloGET /hostile/0/0/0/0 "
      "HTTP/1.1\r\nHost: x\r\n\r\n");
  std::string first = connection.readOneResponse();
  std::string second = connection.readOneResponse();
  EXPECT_EQ(statusOf(first), 200u);
  EXPECT_NE(first.find("\r\n\r\nok"), std::string::npos);
  EXPECT_EQ(statusOf(second), 200u);
  EXPECT_NE(second.find("image/png"), std::string::npos);
}

TEST_F(HostileTest, RangeAbuseIsBounded) {
  std::string many = "bytes=0-0";
  for (int i = 1; i < 200; ++i) many += fmt::format(",{}-{}", i * 3, i * 3);
  EXPECT_EQ(httpRequest(port_, "/hostile.tess", {{"Range", many}}).status, 416u);
  // Overlapping ranges never send a byte twice: one coalesced range.
  std::string overlapping = "bytes=0-999,0-999,0-999,1-998,2-997";
  HttpReply reply = httpRequest(port_, "/hostile.tess", {{"Range", overlapping}});
  EXPECT_EQ(reply.status, 206u);
  EXPECT_EQ(reply.body.size(), 1000u);
  EXPECT_EQ(httpRequest(port_, "/hostile.tess", {{"Range", "bytes=999999999-"}}).status, 416u);
  EXPECT_EQ(httpRequest(port_, "/hostile.tess", {{"Range", "bytes=9223372036854775807-"}}).status,
            416u);
  EXPECT_EQ(httpRequest(port_, "/hostile.tess", {{"Range", "bytes=99999999999999999999-"}}).status,
            200u);  // not a valid number: the header is ignored
  expectStillServing();
}

TEST_F(HostileTest, HugeIndexesAreRefusedWithoutWork) {
  EXPECT_EQ(statusOfGet("/hostile/0/4294967295/0/0"), 404u);
  EXPECT_EQ(statusOfGet("/hostile/4294967295/0/0/0"), 404u);
  EXPECT_EQ(statusOfGet("/hostile/0/0/4294967296/0"), 400u);
  EXPECT_EQ(statusOfGet("/hostile/0/xyz/4294967295/0/0.png"), 404u);
  EXPECT_EQ(statusOfGet("/hostile/0/xyz/0/4294967295/4294967295.png"), 404u);
  EXPECT_EQ(statusOfGet("/hostile/0_files/4294967295/0_0.png"), 404u);
  EXPECT_EQ(statusOfGet("/hostile/0_files/9/4294967295_0.png"), 404u);
  EXPECT_EQ(statusOfGet("/hostile/0_files/9/0_99999999999.png"), 400u);
  expectStillServing();
}

TEST_F(HostileTest, MethodsOtherThanGetHeadOptionsAre405) {
  for (const char* method : {"POST", "PUT", "DELETE", "PATCH", "TRACE", "CONNECT"}) {
    RawConnection connection(port_);
    connection.send(
        fmt::format("{} /healthz HTTP/1.1\r\nHost: x\r\nContent-Length: 0\r\n\r\n", method));
    std::string reply = connection.readOneResponse();
    EXPECT_EQ(statusOf(reply), 405u) << method;
    EXPECT_NE(reply.find("Allow: GET, HEAD, OPTIONS"), std::string::npos) << method;
  }
}

TEST_F(HostileTest, SlowHeaderIsTimedOut) {
  const uint64_t timeouts_before = server_->stats().timeouts;
  RawConnection slow(port_);
  ASSERT_TRUE(slow.send("GET /healthz HTTP/1.1\r\nHost: x\r\n"));  // never finished
  bool timed_out = false;
  std::string reply = slow.readUntilClosed(&timed_out);
  EXPECT_FALSE(timed_out) << "the server kept a slow header open";
  EXPECT_EQ(reply, "");
  // The server counts the timeout just after closing the socket.
  EXPECT_TRUE(eventually([&] { return server_->stats().timeouts > timeouts_before; }));
}

TEST_F(HostileTest, SlowBodyIsTimedOut) {
  RawConnection slow(port_);
  ASSERT_TRUE(slow.send("GET /healthz HTTP/1.1\r\nHost: x\r\nContent-Length: 100\r\n\r\nabc"));
  bool timed_out = false;
  slow.readUntilClosed(&timed_out);
  EXPECT_FALSE(timed_out);
}

TEST_F(HostileTest, ClientThatStopsReadingIsTimedOut) {
  const uint64_t timeouts_before = server_->stats().timeouts;
  RawConnection reader(port_);
  // Far more response bytes than the socket buffers hold, and the client reads none of them.
  std::string requests;
  for (int i = 0; i < 200; ++i) requests += "GET /hostile.tess HTTP/1.1\r\nHost: x\r\n\r\n";
  ASSERT_TRUE(reader.send(requests));
  EXPECT_TRUE(eventually([&] { return server_->stats().timeouts > timeouts_before; }));
  expectStillServing();
}

TEST_F(HostileTest, IdleConnectionIsClosedAfterTheIdleTimeout) {
  RawConnection idle(port_);
  bool timed_out = false;
  EXPECT_EQ(idle.readUntilClosed(&timed_out), "");
  EXPECT_FALSE(timed_out);
  RawConnection kept(port_);
  kept.send("GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n");
  EXPECT_EQ(statusOf(kept.readOneResponse()), 200u);
  kept.readUntilClosed(&timed_out);  // closed once idle after the response
  EXPECT_FALSE(timed_out);
}

TEST(TileServerLoad, ManyIdleConnectionsDoNotStopOthersBeingServed) {
  ServeOptions options;
  options.idle_timeout_ms = 60000;
  options.header_timeout_ms = 60000;
  std::unique_ptr<TileServer> server = startServer({archivePath()}, options);
  ASSERT_NE(server, nullptr);
  std::vector<std::unique_ptr<RawConnection>> idle;
  for (int i = 0; i < 200; ++i) {
    idle.push_back(std::make_unique<RawConnection>(server->port()));
    ASSERT_TRUE(idle.back()->connected());
    // Half of them sit in the middle of a header, the others before any byte.
    if (i % 2) idle.back()->send("GET /hostile/0/0/0/0 HTTP/1.1\r\nHo");
  }
  for (int i = 0; i < 20; ++i) {
    HttpReply reply = httpRequest(server->port(), fmt::format("/hostile/0/0/{}/{}", i % 4, i % 3));
    EXPECT_EQ(reply.status, 200u);
  }
  // Every idle connection is still open and still served once it finishes its request.
  EXPECT_GE(server->stats().connections_open, 200u);
  idle[1]->send("st: x\r\n\r\n");
  EXPECT_EQ(statusOf(idle[1]->readOneResponse()), 200u);
}

TEST(TileServerLoad, ConnectionsBeyondTheLimitAreClosed) {
  ServeOptions options;
  options.max_connections = 2;
  std::unique_ptr<TileServer> server = startServer({archivePath()}, options);
  ASSERT_NE(server, nullptr);
  RawConnection first(server->port()), second(server->port());
  // A served request proves each connection was accepted and counted.
  first.send("GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n");
  second.send("GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n");
  ASSERT_EQ(statusOf(first.readOneResponse()), 200u);
  ASSERT_EQ(statusOf(second.readOneResponse()), 200u);
  RawConnection third(server->port());
  third.send("GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n");
  bool timed_out = false;
  EXPECT_EQ(third.readUntilClosed(&timed_out), "");
  EXPECT_FALSE(timed_out);
  EXPECT_TRUE(eventually([&] { return server->stats().connections_rejected >= 1; }));
}

TEST(TileServerLoad, StopClosesIdleConnectionsAndFinishes) {
  std::unique_ptr<TileServer> server = startServer({archivePath()});
  ASSERT_NE(server, nullptr);
  RawConnection idle(server->port());
  idle.send("GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n");
  ASSERT_EQ(statusOf(idle.readOneResponse()), 200u);
  server->stop();
  bool timed_out = false;
  idle.readUntilClosed(&timed_out);
  EXPECT_FALSE(timed_out);
  EXPECT_TRUE(eventually([&] { return server->stats().connections_open == 0; }));
}

TEST(TileServerLoad, ConcurrentClientsGetCorrectBytes) {
  std::unique_ptr<TileServer> server = startServer({archivePath()});
  ASSERT_NE(server, nullptr);
  const std::string expected = httpRequest(server->port(), "/hostile/0/0/1/1").body;
  ASSERT_FALSE(expected.empty());
  std::vector<std::thread> clients;
  std::atomic<int> wrong{0};
  for (int t = 0; t < 8; ++t)
    clients.emplace_back([&] {
      for (int i = 0; i < 25; ++i)
        if (httpRequest(server->port(), "/hostile/0/0/1/1").body != expected) ++wrong;
    });
  for (std::thread& client : clients) client.join();
  EXPECT_EQ(wrong.load(), 0);
  EXPECT_TRUE(eventually([&] { return server->stats().responses_2xx >= 201; }));
}

}  // namespace
}  // namespace tessera::test
