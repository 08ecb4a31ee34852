#pragma once
// The server side of TLS: an OpenSSL context built from PEM files, with the settings every
// `tessera serve --tls-cert` connection gets (TLS 1.2 and later, forward-secret AEAD ciphers,
// ALPN answered with http/1.1 only).

#include <memory>
#include <string>

#include <boost/asio/ssl/context.hpp>

#include <tessera/result.h>

namespace tessera::detail {

/// Loads the certificate chain (`cert_file`: the server certificate first, then its
/// intermediates) and the private key (`key_file`), and checks that they belong together.
/// Errors name the file and the problem; nothing is kept from a failed load.
[[nodiscard]] Result<std::shared_ptr<boost::asio::ssl::context>> makeServerTlsContext(
    const std::string& cert_file, const std::string& key_file);

}  // namespace tessera::detail
