#include "serve/serve_fixture.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <thread>
#include <mutex>

#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/http.hpp>
#include <fmt/format.h>
#include <gtest/gtest.h>

namespace tessera::test {

namespace net = boost::asio;
namespace http = boost::beast::http;

namespace {

// The archives of this process, removed when it exits.
struct SuiteFolder {
  std::filesystem::path path =
      std::filesystem::path(::testing::TempDir()) / fmt::format("tessera_serve_{}", ::getpid());
  SuiteFolder() { std::filesystem::create_directories(path); }
  ~SuiteFolder() {
    std::error_code ignored;
    std::filesystem::remove_all(path, ignored);
  }
};

std::string suiteFolder() {
  static const SuiteFolder folder;
  return folder.path.string();
}

}  // namespace

std::string servedArchive(const std::string& name, uint32_t width_px, uint32_t height_px,
                          uint32_t channels, Codec codec, uint32_t tile_size_px,
                          uint32_t border_px) {
  static std::mutex mutex;  // guards built
  static std::map<std::string, std::string> built;
  std::lock_guard lock(mutex);
  if (auto it = built.find(name); it != built.end()) return it->second;
  BuildOptions options;
  options.inputs = {fmt::format("synthetic:{}x{}:7:{}", width_px, height_px, channels)};
  options.output = suiteFolder() + "/" + name + ".tess";
  options.codec = codec;
  options.tile_size_px = tile_size_px;
  options.border_px = border_px;
  options.threads = 2;
  Result<BuildReport> report = buildArchive(options);
  if (!report) {
    ADD_FAILURE() << report.error().message;
    return "";
  }
  built[name] = options.output;
  return options.output;
}

std::unique_ptr<TileServer> startServer(const std::vector<std::string>& paths,
                                        ServeOptions options) {
  options.paths = paths;
  options.port = 0;
  options.bind_address = "127.0.0.1";
  if (options.threads == 0) options.threads = 2;
  Result<std::unique_ptr<TileServer>> server = TileServer::start(options);
  if (!server) {
    ADD_FAILURE() << server.error().message;
    return nullptr;
  }
  return std::move(*server);
}

HttpReply httpRequest(uint16_t port, const std::string& target,
                      const std::map<std::string, std::string>& headers,
                      const std::string& method) {
  net::io_context ioc;
  net::ip::tcp::socket socket(ioc);
  socket.connect({net::ip::make_address("127.0.0.1"), port});
  http::request<http::empty_body> request{http::string_to_verb(method), target, 11};
  request.set(http::field::host, "127.0.0.1");
  for (const auto& [name, value] : headers) request.set(name, value);
  http::write(socket, request);
  boost::beast::flat_buffer buffer;
  http::response_parser<http::string_body> parser;
  parser.body_limit(boost::none);
  if (method == "HEAD") parser.skip(true);
  http::read(socket, buffer, parser);
  HttpReply reply;
  reply.status = parser.get().result_int();
  for (const auto& field : parser.get()) {
    std::string name(field.name_string());
    for (char& c : name) c = char(std::tolower(uint8_t(c)));
    reply.headers[name] = std::string(field.value());
  }
  reply.body = parser.get().body();
  boost::system::error_code ignored;
  socket.shutdown(net::ip::tcp::socket::shutdown_both, ignored);
  return reply;
}

RawConnection::RawConnection(uint16_t port) {
  fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(port);
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  timeval guard{10, 0};
  ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &guard, sizeof guard);
  if (::connect(fd_, reinterpret_cast<sockaddr*>(&address), sizeof address) != 0) {
    ::close(fd_);
    fd_ = -1;
  }
}

RawConnection::~RawConnection() {
  if (fd_ >= 0) ::close(fd_);
}

bool RawConnection::send(const std::string& bytes) {
  size_t sent = 0;
  while (sent < bytes.size()) {
    ssize_t n = ::send(fd_, bytes.data() + sent, bytes.size() - sent, MSG_NOSIGNAL);
    if (n <= 0) return false;
    sent += size_t(n);
  }
  return true;
}

std::string RawConnection::readUntilClosed(bool* timed_out) {
  std::string out = std::move(pending_);
  pending_.clear();
  if (timed_out) *timed_out = false;
  char chunk[16384];
  while (true) {
    ssize_t n = ::recv(fd_, chunk, sizeof chunk, 0);
    if (n > 0) {
      out.append(chunk, size_t(n));
      continue;
    }
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK) && timed_out) *timed_out = true;
    break;
  }
  return out;
}

std::string RawConnection::readOneResponse() {
  char chunk[16384];
  while (true) {
    size_t end = pending_.find("\r\n\r\n");
    if (end != std::string::npos) {
      size_t length = 0;
      std::string head = pending_.substr(0, end);
      std::string lower = head;
      for (char& c : lower) c = char(std::tolower(uint8_t(c)));
      if (size_t at = lower.find("content-length:"); at != std::string::npos)
        length = std::stoul(head.substr(at + 15));
      if (pending_.size() >= end + 4 + length) {
        std::string response = pending_.substr(0, end + 4 + length);
        pending_.erase(0, end + 4 + length);
        return response;
      }
    }
    ssize_t n = ::recv(fd_, chunk, sizeof chunk, 0);
    if (n <= 0) {
      std::string partial = std::move(pending_);
      pending_.clear();
      return partial;
    }
    pending_.append(chunk, size_t(n));
  }
}

bool eventually(const std::function<bool()>& condition) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (!condition()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::yield();
  }
  return true;
}

unsigned statusOf(const std::string& bytes) {
  if (bytes.size() < 12 || bytes.compare(0, 5, "HTTP/") != 0) return 0;
  return unsigned(std::atoi(bytes.substr(9, 3).c_str()));
}

}  // namespace tessera::test
