#pragma once
// Self-signed certificates made with the OpenSSL API, for the TLS tests of the server.

#include <string>

namespace tessera::test {

struct PemPair {
  std::string cert, key;
};

/// A self-signed P-256 certificate for 127.0.0.1 (subjectAltName, so that curl's host check
/// passes), valid for a day, with its private key; both PEM.
PemPair makeSelfSigned(long serial);

}  // namespace tessera::test
