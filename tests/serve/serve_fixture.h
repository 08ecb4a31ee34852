#pragma once
// Shared pieces of the server tests: archives built once per process into a temp folder, a
// Beast client for well-formed requests and a raw socket for hostile ones.

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <tessera/build.h>
#include <tessera/serve.h>

namespace tessera::test {

/// Builds (once per process) an archive of "synthetic:WxH:seed:channels" into a temp folder
/// holding only the archives of this suite, named `<name>.tess`; returns its path. Fails the
/// test and returns "" when the build fails.
std::string servedArchive(const std::string& name, uint32_t width_px, uint32_t height_px,
                          uint32_t channels, Codec codec, uint32_t tile_size_px,
                          uint32_t border_px);

/// Starts a server on 127.0.0.1 port 0 with `options` (paths and port overridden); fails the
/// test and returns null on error.
std::unique_ptr<TileServer> startServer(const std::vector<std::string>& paths,
                                        ServeOptions options = {});

struct HttpReply {
  unsigned status = 0;
  std::map<std::string, std::string> headers;  ///< lower-case names
  std::string body;
  std::string header(const std::string& name) const {
    auto it = headers.find(name);
    return it == headers.end() ? "" : it->second;
  }
};

/// One request on a fresh connection, with Beast's synchronous client. `method` is GET or
/// HEAD; `headers` are added as given.
HttpReply httpRequest(uint16_t port, const std::string& target,
                      const std::map<std::string, std::string>& headers = {},
                      const std::string& method = "GET");

/// A blocking TCP connection to 127.0.0.1:port for hand-written bytes. A 10 s receive timeout
/// guards every read so a server bug fails the test instead of hanging it.
class RawConnection {
 public:
  explicit RawConnection(uint16_t port);
  ~RawConnection();
  RawConnection(const RawConnection&) = delete;
  RawConnection& operator=(const RawConnection&) = delete;
  bool connected() const { return fd_ >= 0; }
  /// Sends all of `bytes`; false if the peer has closed.
  bool send(const std::string& bytes);
  /// Reads until the server closes the connection (or the guard timeout, which sets
  /// `timed_out`). Returns everything read.
  std::string readUntilClosed(bool* timed_out = nullptr);
  /// Reads one response whose framing is Content-Length (enough for our tests).
  std::string readOneResponse();

 private:
  int fd_ = -1;
  std::string pending_;
};

/// Polls `condition` until it holds or 10 s pass; returns its last value. For counters the
/// server updates just after a response's last byte is written, which a client can see first.
bool eventually(const std::function<bool()>& condition);

/// The status code of the first response in `bytes` ("HTTP/1.1 404 ..." -> 404), 0 if none.
unsigned statusOf(const std::string& bytes);

}  // namespace tessera::test
