#include "tls_context.h"

#include <openssl/err.h>
#include <openssl/ssl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include <fmt/format.h>

namespace tessera::detail {

namespace ssl = boost::asio::ssl;

namespace {

// OpenSSL's reason for the last failure, which says more than the error code Asio hands back
// ("no start line", "key values mismatch"); clears the queue.
std::string lastOpenSslError(const boost::system::error_code& ec) {
  std::string reason;
  for (unsigned long code; (code = ERR_get_error()) != 0;) {
    char text[256];
    ERR_error_string_n(code, text, sizeof text);
    reason = text;
  }
  return reason.empty() ? ec.message() : reason;
}

Result<void> checkReadable(const std::string& path, const char* what) {
  if (path.empty())
    return fail(ErrorCode::kInvalidArgument, fmt::format("serve: no {} file", what));
  if (::access(path.c_str(), R_OK) != 0)
    return fail(errno == ENOENT ? ErrorCode::kNotFound : ErrorCode::kIo,
                fmt::format("{}: cannot read the TLS {}: {}", path, what, std::strerror(errno)));
  // OpenSSL's read of a FIFO would wait for a writer, stalling a start or a SIGHUP reload.
  struct stat status {};
  if (::stat(path.c_str(), &status) != 0 || !S_ISREG(status.st_mode))
    return fail(ErrorCode::kIo, fmt::format("{}: the TLS {} is not a regular file", path, what));
  return {};
}

// The client lists the protocols it speaks; the server speaks HTTP/1.1 only, and saying so
// keeps a client that offers h2 first from guessing.
int selectHttp11(SSL*, const unsigned char** out, unsigned char* out_length,
                 const unsigned char* offered, unsigned int offered_length, void*) {
  static const unsigned char kHttp11[] = {8, 'h', 't', 't', 'p', '/', '1', '.', '1'};
  unsigned char* chosen = nullptr;
  if (SSL_select_next_proto(&chosen, out_length, kHttp11, sizeof kHttp11, offered,
                            offered_length) != OPENSSL_NPN_NEGOTIATED)
    return SSL_TLSEXT_ERR_NOACK;
  *out = chosen;
  return SSL_TLSEXT_ERR_OK;
}

}  // namespace

Result<std::shared_ptr<ssl::context>> makeServerTlsContext(const std::string& cert_file,
                                                           const std::string& key_file) {
  TESSERA_TRY(checkReadable(cert_file, "certificate"));
  TESSERA_TRY(checkReadable(key_file, "key"));
  ERR_clear_error();
  auto context = std::make_shared<ssl::context>(ssl::context::tls_server);
  SSL_CTX* native = context->native_handle();
  // TLS 1.0 and 1.1 are deprecated (RFC 8996); compression invites CRIME.
  SSL_CTX_set_min_proto_version(native, TLS1_2_VERSION);
  context->set_options(ssl::context::default_workarounds | ssl::context::no_compression |
                       ssl::context::single_dh_use);
  // TLS 1.2: ephemeral key exchange and AEAD only (TLS 1.3's suites are all of that kind).
  SSL_CTX_set_cipher_list(native, "ECDHE+AESGCM:ECDHE+CHACHA20:DHE+AESGCM:DHE+CHACHA20");
  SSL_CTX_set_alpn_select_cb(native, &selectHttp11, nullptr);
  // An encrypted key would make OpenSSL ask for its passphrase on the terminal, which blocks a
  // server reloading on SIGHUP: refuse it instead.
  SSL_CTX_set_default_passwd_cb(native, [](char*, int, int, void*) { return 0; });
  boost::system::error_code ec;
  context->use_certificate_chain_file(cert_file, ec);
  if (ec)
    return fail(ErrorCode::kInvalidArgument, fmt::format("{}: not a PEM certificate chain: {}",
                                                         cert_file, lastOpenSslError(ec)));
  context->use_private_key_file(key_file, ssl::context::pem, ec);
  // OpenSSL checks the pair as it loads the key ("key values mismatch"), and again below for
  // the case where it does not.
  const std::string key_error = ec ? lastOpenSslError(ec) : std::string();
  if (ec && key_error.find("mismatch") == std::string::npos)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: not a PEM private key (unencrypted): {}", key_file, key_error));
  if (ec || SSL_CTX_check_private_key(native) != 1) {
    ERR_clear_error();
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: the private key does not match the certificate in {}", key_file,
                            cert_file));
  }
  return context;
}

}  // namespace tessera::detail
