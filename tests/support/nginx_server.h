#pragma once
// nginx on loopback for the HTTP tests: a private configuration in a temp folder, a free
// port found by binding port 0, readiness by polling connect. Serves `root` at /, and the same
// files at /noranges/ (max_ranges 0: answers ranges with the whole file), /slow/ (limit_rate)
// and /unavailable/ (always 503), plus /status (stub_status: connection counts); on a second
// port the same over cleartext HTTP/2 (h2c, prior knowledge only), and on a third over HTTPS
// with HTTP/2 offered by ALPN (a self-signed certificate made with the openssl tool, when
// it is installed).

#include <sys/types.h>

#include <cstdint>
#include <memory>
#include <string>

#include <tessera/result.h>

namespace tessera::test {

/// Owned by one thread (the test's).
class NginxServer {
 public:
  static constexpr const char* kBinary = "/usr/sbin/nginx";
  /// True when the nginx binary is installed (scripts/install-deps.sh installs it).
  static bool available();
  /// Starts nginx; `work_dir` (created) holds its configuration, logs and temp files.
  [[nodiscard]] static Result<std::unique_ptr<NginxServer>> start(const std::string& root,
                                                                  const std::string& work_dir);
  ~NginxServer();
  NginxServer(const NginxServer&) = delete;
  NginxServer& operator=(const NginxServer&) = delete;

  /// "http://127.0.0.1:PORT/<path>" (HTTP/1.1 port).
  std::string url(const std::string& path) const;
  /// The same on the h2c port.
  std::string h2cUrl(const std::string& path) const;
  /// The same over HTTPS ("https://127.0.0.1:PORT/<path>"), or empty without openssl.
  std::string httpsUrl(const std::string& path) const;
  /// The HTTPS server's self-signed certificate (PEM, for 127.0.0.1): the CA file a client
  /// that checks certificates needs. Empty without openssl.
  std::string certificateFile() const;
  /// Connections nginx accepted so far (stub_status "accepts"), the status request included.
  [[nodiscard]] Result<uint64_t> acceptedConnections() const;

 private:
  NginxServer(pid_t pid, uint16_t port, uint16_t h2c_port, uint16_t tls_port, std::string work_dir)
      : pid_(pid),
        port_(port),
        h2c_port_(h2c_port),
        tls_port_(tls_port),
        work_dir_(std::move(work_dir)) {}
  pid_t pid_;
  uint16_t port_;
  uint16_t h2c_port_;
  uint16_t tls_port_;  ///< 0: no HTTPS server
  std::string work_dir_;
};

/// A free TCP port on 127.0.0.1 now (bound to port 0, read back, closed): the caller must
/// expect to lose a race for it and retry.
uint16_t freeLoopbackPort();

/// Polls connect() to 127.0.0.1:port until it succeeds, `alive()` says the server process is
/// gone, or 10 s pass.
bool waitForPort(uint16_t port, pid_t pid);

}  // namespace tessera::test
