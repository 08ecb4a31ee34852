// `tessera serve` over TLS: certificates made here with the OpenSSL API (self-signed, for
// 127.0.0.1), an archive read through Tessera's own HTTP client over https, handshake errors
// closed cleanly, certificate reload (a broken file keeps the old one), startup errors naming
// the file, and access control unchanged under TLS.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/ssl.h>
#include <openssl/x509v3.h>
#include <sys/socket.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <tessera/http_source.h>

#include "serve/serve_fixture.h"
#include "serve/test_certificate.h"

namespace tessera::test {
namespace {

namespace fs = std::filesystem;

constexpr std::string_view kToken = "a-token-for-tls-tests-0123456789";

// Written aside and renamed into place, as a certificate renewal would do.
void writeFile(const std::string& path, const std::string& text) {
  std::ofstream(path + ".part", std::ios::binary) << text;
  fs::rename(path + ".part", path);
}

std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// The SHA-256 of a certificate as hex; empty for none.
std::string fingerprint(X509* cert) {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  std::string hex;
  if (cert && X509_digest(cert, EVP_sha256(), digest, &length) == 1)
    for (unsigned int i = 0; i < length; ++i) hex += fmt::format("{:02x}", digest[i]);
  return hex;
}

// The SHA-256 of the certificate a TLS handshake with 127.0.0.1:port presents, as hex; empty
// when the handshake fails. `max_version` caps what this client offers.
std::string servedFingerprint(uint16_t port, int max_version = TLS1_3_VERSION) {
  std::unique_ptr<SSL_CTX, decltype(&SSL_CTX_free)> context(SSL_CTX_new(TLS_client_method()),
                                                            SSL_CTX_free);
  SSL_CTX_set_min_proto_version(context.get(), TLS1_VERSION);
  SSL_CTX_set_max_proto_version(context.get(), max_version);
  // TLS 1.0/1.1 need security level 0 in OpenSSL 3 to be offered at all.
  if (max_version < TLS1_2_VERSION) SSL_CTX_set_security_level(context.get(), 0);
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(port);
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  timeval guard{10, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &guard, sizeof guard);
  std::string hex;
  if (::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0) {
    SSL* ssl = SSL_new(context.get());
    SSL_set_fd(ssl, fd);
    if (SSL_connect(ssl) == 1) {
      X509* peer = SSL_get1_peer_certificate(ssl);
      hex = fingerprint(peer);
      X509_free(peer);
      SSL_shutdown(ssl);
    }
    SSL_free(ssl);
  }
  ::close(fd);
  return hex;
}

// Over TLS to 127.0.0.1:port: handshakes, sends `request` and closes the socket at once,
// reading nothing. The server's answer then meets a closed socket (a reset on loopback), so
// its next write fails with EPIPE. False when the handshake fails.
bool sendAndVanish(uint16_t port, const std::string& request) {
  std::unique_ptr<SSL_CTX, decltype(&SSL_CTX_free)> context(SSL_CTX_new(TLS_client_method()),
                                                            SSL_CTX_free);
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(port);
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  timeval guard{10, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &guard, sizeof guard);
  bool sent = false;
  if (::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0) {
    SSL* ssl = SSL_new(context.get());
    SSL_set_fd(ssl, fd);
    sent = SSL_connect(ssl) == 1 && SSL_write(ssl, request.data(), int(request.size())) > 0;
    SSL_free(ssl);
  }
  ::close(fd);
  return sent;
}

std::string fingerprintOf(const std::string& pem) {
  std::unique_ptr<BIO, decltype(&BIO_free)> bio(BIO_new_mem_buf(pem.data(), int(pem.size())),
                                                BIO_free);
  std::unique_ptr<X509, decltype(&X509_free)> cert(
      PEM_read_bio_X509(bio.get(), nullptr, nullptr, nullptr), X509_free);
  return fingerprint(cert.get());
}

class TlsServe : public ::testing::Test {
 protected:
  void SetUp() override {
    archive_ = servedArchive("tlsplain", 640, 480, 3, Codec::kPng, 128, 0);
    protected_archive_ = servedArchive("tlsguarded", 300, 200, 3, Codec::kZstd, 64, 0);
    dir_ = fs::path(archive_).parent_path() /
           fmt::format("tls-{}-{}", ::getpid(),
                       ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
    cert_file_ = (dir_ / "cert.pem").string();
    key_file_ = (dir_ / "key.pem").string();
    first_ = makeSelfSigned(1);
    writeFile(cert_file_, first_.cert);
    writeFile(key_file_, first_.key);
  }
  void TearDown() override {
    server_.reset();
    std::error_code ignored;
    fs::remove_all(dir_, ignored);
  }

  ServeOptions tlsOptions() const {
    ServeOptions options;
    options.tls_cert_file = cert_file_;
    options.tls_key_file = key_file_;
    options.threads = 2;
    return options;
  }
  std::string url(const std::string& path) const {
    return fmt::format("https://127.0.0.1:{}/{}", server_->port(), path);
  }

  std::string archive_, protected_archive_;
  fs::path dir_;
  std::string cert_file_, key_file_;
  PemPair first_;
  std::unique_ptr<TileServer> server_;
};

TEST_F(TlsServe, TheClientReadsAnArchiveOverHttpsWithTheTestCertificateAsItsCa) {
  server_ = startServer({archive_}, tlsOptions());
  ASSERT_TRUE(server_);
  EXPECT_TRUE(server_->tls());
  HttpOptions options;
  options.ca_file = cert_file_;
  Result<std::shared_ptr<ByteSource>> source = openHttpSource(url("tlsplain.tess"), options);
  ASSERT_TRUE(source) << source.error().message;
  const std::string expected = readFile(archive_);
  ASSERT_EQ((*source)->sizeBytes(), expected.size());
  std::string bytes(expected.size(), '\0');
  ASSERT_TRUE((*source)->read(0, {reinterpret_cast<uint8_t*>(bytes.data()), bytes.size()}));
  EXPECT_TRUE(bytes == expected);
  // The server offers only http/1.1 by ALPN, and the client reports it.
  const LinkStats stats = *(*source)->linkStats();
  EXPECT_GE(stats.connections, 1u);
  EXPECT_EQ(stats.http1_connections, stats.connections);
  EXPECT_EQ(stats.http2_connections, 0u);

  // Without the CA file the self-signed certificate is not trusted; with checks off it is
  // read anyway (the explicit insecure switch).
  HttpOptions system_cas;
  system_cas.max_attempts = 1;
  Result<std::shared_ptr<ByteSource>> untrusted = openHttpSource(url("tlsplain.tess"), system_cas);
  ASSERT_FALSE(untrusted);
  EXPECT_NE(untrusted.error().message.find(url("tlsplain.tess")), std::string::npos);
  HttpOptions insecure;
  insecure.verify_tls = false;
  EXPECT_TRUE(openHttpSource(url("tlsplain.tess"), insecure));
}

TEST_F(TlsServe, PlainHttpAndOldTlsAreClosedCleanlyAndCounted) {
  server_ = startServer({archive_}, tlsOptions());
  ASSERT_TRUE(server_);
  RawConnection plain(server_->port());
  ASSERT_TRUE(plain.connected());
  plain.send("GET /tlsplain.tess HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n");
  bool timed_out = false;
  const std::string reply = plain.readUntilClosed(&timed_out);
  EXPECT_FALSE(timed_out);
  EXPECT_EQ(reply.find("HTTP/"), std::string::npos) << "no plain-text answer on the TLS port";
  EXPECT_EQ(servedFingerprint(server_->port(), TLS1_1_VERSION), "") << "TLS 1.1 refused";
  EXPECT_TRUE(eventually([&] { return server_->stats().tls_handshake_errors >= 2; }));
  // The server is unharmed.
  EXPECT_EQ(servedFingerprint(server_->port()), fingerprintOf(first_.cert));
}

// A client that connects and never says hello is closed at the header timeout, counted as a
// timeout rather than a failed handshake.
TEST_F(TlsServe, SilentClientIsClosedAtTheHeaderTimeout) {
  ServeOptions options = tlsOptions();
  options.header_timeout_ms = 150;
  server_ = startServer({archive_}, options);
  ASSERT_TRUE(server_);
  RawConnection silent(server_->port());
  ASSERT_TRUE(silent.connected());
  bool timed_out = false;
  EXPECT_EQ(silent.readUntilClosed(&timed_out), "");
  EXPECT_FALSE(timed_out) << "the server closed the connection before the client gave up";
  EXPECT_TRUE(eventually([&] { return server_->stats().timeouts >= 1; }));
  EXPECT_EQ(server_->stats().tls_handshake_errors, 0u);
  EXPECT_EQ(servedFingerprint(server_->port()), fingerprintOf(first_.cert));
}

// OpenSSL writes records with write(), which raises SIGPIPE on such a socket: the server's
// close_notify after a `Connection: close` response would kill the process (this one) if the
// I/O threads did not block the signal.
TEST_F(TlsServe, ClientsVanishingBeforeTheirResponseLeaveTheServerServing) {
  server_ = startServer({archive_}, tlsOptions());
  ASSERT_TRUE(server_);
  for (int i = 0; i < 20; ++i)
    ASSERT_TRUE(sendAndVanish(server_->port(),
                              "GET /tlsplain/0/0/0/0 HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                              "Connection: close\r\n\r\n"));
  EXPECT_TRUE(eventually([&] { return server_->stats().requests >= 20; }));
  EXPECT_EQ(servedFingerprint(server_->port()), fingerprintOf(first_.cert));
}

TEST_F(TlsServe, ReloadSwapsTheCertificateAndABrokenFileKeepsTheOldOne) {
  server_ = startServer({archive_}, tlsOptions());
  ASSERT_TRUE(server_);
  const std::string first = fingerprintOf(first_.cert);
  ASSERT_FALSE(first.empty());
  EXPECT_EQ(servedFingerprint(server_->port()), first);

  const PemPair second = makeSelfSigned(2);
  writeFile(cert_file_, second.cert);
  writeFile(key_file_, second.key);
  ASSERT_TRUE(server_->reloadTls());
  const std::string second_print = fingerprintOf(second.cert);
  EXPECT_NE(second_print, first);
  EXPECT_EQ(servedFingerprint(server_->port()), second_print);

  // A truncated certificate, then a key of another pair: refused, naming the file, and the
  // second certificate stays.
  writeFile(cert_file_, second.cert.substr(0, second.cert.size() / 2));
  Result<void> broken = server_->reloadTls();
  ASSERT_FALSE(broken);
  EXPECT_NE(broken.error().message.find(cert_file_), std::string::npos) << broken.error().message;
  writeFile(cert_file_, second.cert);
  writeFile(key_file_, first_.key);
  Result<void> mismatched = server_->reloadTls();
  ASSERT_FALSE(mismatched);
  EXPECT_NE(mismatched.error().message.find(key_file_), std::string::npos);
  EXPECT_NE(mismatched.error().message.find("does not match"), std::string::npos);
  EXPECT_EQ(servedFingerprint(server_->port()), second_print);
}

TEST_F(TlsServe, StartupFailsNamingAMissingOrMismatchedFile) {
  ServeOptions missing = tlsOptions();
  missing.paths = {archive_};
  missing.port = 0;
  missing.tls_cert_file = (dir_ / "absent.pem").string();
  Result<std::unique_ptr<TileServer>> started = TileServer::start(missing);
  ASSERT_FALSE(started);
  EXPECT_NE(started.error().message.find(missing.tls_cert_file), std::string::npos);

  ServeOptions mismatched = tlsOptions();
  mismatched.paths = {archive_};
  mismatched.port = 0;
  writeFile(key_file_, makeSelfSigned(3).key);
  started = TileServer::start(mismatched);
  ASSERT_FALSE(started);
  EXPECT_NE(started.error().message.find(key_file_), std::string::npos);

  ServeOptions plain;
  plain.paths = {archive_};
  plain.port = 0;
  Result<std::unique_ptr<TileServer>> plain_server = TileServer::start(plain);
  ASSERT_TRUE(plain_server);
  EXPECT_FALSE((*plain_server)->reloadTls()) << "nothing to reload without TLS";
}

TEST_F(TlsServe, TokenProtectedArchivesStillRefuseOverTls) {
  const std::string access_file = (dir_ / "access.json").string();
  writeFile(access_file, fmt::format(R"({{"public": ["tlsplain"], "tokens": [{{"token": "{}",
    "archives": ["tlsguarded"]}}]}})",
                                     kToken));
  ServeOptions options = tlsOptions();
  options.access_file = access_file;
  server_ = startServer({archive_, protected_archive_}, options);
  ASSERT_TRUE(server_);
  HttpOptions anonymous;
  anonymous.ca_file = cert_file_;
  Result<std::shared_ptr<ByteSource>> refused = openHttpSource(url("tlsguarded.tess"), anonymous);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("401"), std::string::npos) << refused.error().message;
  EXPECT_TRUE(openHttpSource(url("tlsplain.tess"), anonymous));
  HttpOptions with_token = anonymous;
  with_token.bearer_token = std::string(kToken);
  Result<std::shared_ptr<ByteSource>> granted = openHttpSource(url("tlsguarded.tess"), with_token);
  ASSERT_TRUE(granted) << granted.error().message;
  EXPECT_EQ((*granted)->sizeBytes(), fs::file_size(protected_archive_));
}

}  // namespace
}  // namespace tessera::test
