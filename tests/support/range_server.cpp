#include "support/range_server.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>

#include <fmt/format.h>

namespace tessera::test {

namespace {

bool sendAll(int fd, const void* data, size_t size) {
  const char* bytes = static_cast<const char*>(data);
  while (size > 0) {
    const ssize_t n = ::send(fd, bytes, size, MSG_NOSIGNAL);
    if (n <= 0) return false;
    bytes += n;
    size -= size_t(n);
  }
  return true;
}

std::string headerValue(const std::string& head, const std::string& name) {
  std::string lower = head;
  std::transform(lower.begin(), lower.end(), lower.begin(), ::tolower);
  const size_t at = lower.find("\r\n" + name + ":");
  if (at == std::string::npos) return "";
  size_t begin = at + 2 + name.size() + 1;
  const size_t end = head.find("\r\n", begin);
  while (begin < end && head[begin] == ' ') ++begin;
  return head.substr(begin, end - begin);
}

}  // namespace

RangeServer::RangeServer(std::vector<uint8_t> bytes, std::string etag)
    : bytes_(std::move(bytes)), etag_(std::move(etag)) {
  listen_fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t length = sizeof(address);
  if (listen_fd_ >= 0 &&
      ::bind(listen_fd_, reinterpret_cast<sockaddr*>(&address), sizeof(address)) == 0 &&
      ::listen(listen_fd_, 64) == 0 &&
      ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&address), &length) == 0)
    port_ = ntohs(address.sin_port);
  acceptor_ = std::thread([this] { acceptLoop(); });
}

RangeServer::~RangeServer() {
  std::vector<std::thread> connections;
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
    for (int fd : connection_fds_) ::shutdown(fd, SHUT_RDWR);
  }
  changed_.notify_all();
  ::shutdown(listen_fd_, SHUT_RDWR);
  acceptor_.join();
  {
    std::lock_guard lock(mutex_);
    connections.swap(connections_);
  }
  for (std::thread& connection : connections) connection.join();
  ::close(listen_fd_);
}

std::string RangeServer::url() const {
  return fmt::format("http://127.0.0.1:{}/file.tess", port_);
}

void RangeServer::setPlan(std::function<RangeReply(uint64_t)> plan) {
  std::lock_guard lock(mutex_);
  plan_ = std::move(plan);
}

void RangeServer::replace(std::vector<uint8_t> bytes, std::string etag, bool honour_conditionals) {
  std::lock_guard lock(mutex_);
  bytes_ = std::move(bytes);
  etag_ = std::move(etag);
  honour_conditionals_ = honour_conditionals;
}

void RangeServer::setLatency(std::chrono::milliseconds latency) {
  std::lock_guard lock(mutex_);
  latency_ = latency;
}

std::vector<SeenRequest> RangeServer::seen() const {
  std::lock_guard lock(mutex_);
  return seen_;
}

void RangeServer::waitStalled() {
  std::unique_lock lock(mutex_);
  changed_.wait(lock, [&] { return stalled_ || stopping_; });
}

void RangeServer::acceptLoop() {
  for (;;) {
    const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
    std::lock_guard lock(mutex_);
    if (fd < 0 || stopping_) {
      if (fd >= 0) ::close(fd);
      return;
    }
    connection_fds_.push_back(fd);
    connections_.emplace_back([this, fd] { serve(fd); });
  }
}

void RangeServer::serve(int fd) {
  std::string buffer;
  char chunk[4096];
  for (;;) {
    size_t end;
    while ((end = buffer.find("\r\n\r\n")) == std::string::npos) {
      const ssize_t n = ::recv(fd, chunk, sizeof(chunk), 0);
      if (n <= 0) {
        end = std::string::npos;
        break;
      }
      buffer.append(chunk, size_t(n));
    }
    if (end == std::string::npos) break;
    const std::string head = "\r\n" + buffer.substr(0, end + 2);
    buffer.erase(0, end + 4);
    SeenRequest request;
    request.method = head.substr(2, head.find(' ', 2) - 2);
    request.range = headerValue(head, "range");
    request.if_match = headerValue(head, "if-match");
    request.if_range = headerValue(head, "if-range");
    request.if_unmodified_since = headerValue(head, "if-unmodified-since");
    size_t index = 0;
    const bool keep_open = handle(fd, request, index);
    {
      std::lock_guard lock(mutex_);
      answered_round_max_ = std::max(answered_round_max_, seen_[index].round);
    }
    if (!keep_open) break;
  }
  std::lock_guard lock(mutex_);
  auto it = std::find(connection_fds_.begin(), connection_fds_.end(), fd);
  if (it != connection_fds_.end()) connection_fds_.erase(it);
  ::close(fd);
}

bool RangeServer::sendMultipart(int fd, RangeReply::Kind kind, const std::string& range,
                                const std::vector<uint8_t>& bytes, const std::string& validator) {
  std::vector<std::pair<uint64_t, uint64_t>> ranges;
  for (size_t pos = range.find('=') + 1; pos != 0 && pos < range.size();) {
    uint64_t first = 0, last = 0;
    if (std::sscanf(range.c_str() + pos, "%lu-%lu", &first, &last) != 2 || first > last ||
        last >= bytes.size())
      return false;
    ranges.emplace_back(first, last);
    const size_t comma = range.find(',', pos);
    pos = comma == std::string::npos ? range.size() : comma + 1;
  }
  std::string body;
  if (kind == RangeReply::Kind::kMultipartOversized) body.assign(1 << 20, 'p');
  for (auto it = ranges.rbegin(); it != ranges.rend(); ++it) {
    const bool first = it + 1 == ranges.rend();
    const int shift = kind == RangeReply::Kind::kMultipartWrongRange ||
                              (first && kind == RangeReply::Kind::kMultipartFirstMislabelled)
                          ? 1
                          : 0;
    body += fmt::format(
        "\r\n--SEP\r\nContent-Type: application/octet-stream\r\n"
        "Content-Range: bytes {}-{}/{}\r\n\r\n",
        it->first + shift, it->second + shift, bytes.size());
    const size_t data_at = body.size();
    body.append(reinterpret_cast<const char*>(bytes.data()) + it->first,
                it->second - it->first + 1);
    if (first && kind == RangeReply::Kind::kMultipartFirstCorrupt)
      for (size_t i = data_at; i < body.size(); ++i) body[i] = char(~body[i]);
  }
  body += "\r\n--SEP--\r\n";
  const std::string head = fmt::format(
      "HTTP/1.1 206 Partial Content\r\n{}Content-Type: multipart/byteranges; boundary=SEP\r\n"
      "Content-Length: {}\r\n\r\n",
      validator, body.size());
  return sendAll(fd, head.data(), head.size()) && sendAll(fd, body.data(), body.size());
}

bool RangeServer::handle(int fd, const SeenRequest& seen, size_t& index) {
  std::unique_lock lock(mutex_);
  index = seen_.size();
  SeenRequest request = seen;
  request.round = answered_round_max_ + 1;
  seen_.push_back(request);
  const RangeReply reply = plan_ ? plan_(index) : RangeReply{};
  const std::vector<uint8_t> bytes = bytes_;
  const std::string etag = etag_;
  const bool honour = honour_conditionals_;
  const std::chrono::milliseconds latency = latency_;
  lock.unlock();
  // The link's delay: the answer leaves this long after the request came.
  if (latency.count() > 0) std::this_thread::sleep_for(latency);
  const std::string validator =
      etag.empty() ? "Last-Modified: Mon, 23 Nov 2026 10:00:00 GMT\r\n" : "ETag: " + etag + "\r\n";
  const std::string version = etag.empty() ? "Mon, 23 Nov 2026 10:00:00 GMT" : etag;
  auto sendHead = [&](int status, const std::string& text, const std::string& extra,
                      uint64_t length) {
    const std::string out =
        fmt::format("HTTP/1.1 {} {}\r\n{}Accept-Ranges: bytes\r\nContent-Length: {}\r\n{}\r\n",
                    status, text, validator, length, extra);
    return sendAll(fd, out.data(), out.size());
  };
  if (reply.kind == RangeReply::Kind::kStatus) {
    const std::string body = fmt::format("status {}\n", reply.status);
    const std::string extra =
        reply.retry_after.empty() ? "" : "Retry-After: " + reply.retry_after + "\r\n";
    return sendHead(reply.status, "Planned", extra, body.size()) &&
           (request.method == "HEAD" || sendAll(fd, body.data(), body.size()));
  }
  const bool whole = reply.kind == RangeReply::Kind::kWholeFile || request.range.empty() ||
                     (honour && !request.if_range.empty() && request.if_range != version);
  if (honour && !request.if_match.empty() && request.if_match != etag)
    return sendHead(412, "Precondition Failed", "", 0);
  if (whole) {
    if (!sendHead(200, "OK", "", bytes.size())) return false;
    return request.method == "HEAD" || sendAll(fd, bytes.data(), bytes.size());
  }
  const bool multipart = reply.kind >= RangeReply::Kind::kMultipart;
  if (multipart && request.range.find(',') != std::string::npos)
    return sendMultipart(fd, reply.kind, request.range, bytes, validator);
  uint64_t first = 0, last = 0;
  if (std::sscanf(request.range.c_str(), "bytes=%lu-%lu", &first, &last) != 2 || first > last ||
      first >= bytes.size()) {
    return sendHead(416, "Range Not Satisfiable",
                    fmt::format("Content-Range: bytes */{}\r\n", bytes.size()), 0);
  }
  last = std::min<uint64_t>(last, bytes.size() - 1);
  uint64_t shown_first = first, shown_last = last;
  if (reply.kind == RangeReply::Kind::kWrongRange && first + 1 < bytes.size()) {
    ++shown_first;
    shown_last = std::min<uint64_t>(last + 1, bytes.size() - 1);
  }
  const uint64_t length = last - first + 1;
  if (!sendHead(
          206, "Partial Content",
          fmt::format("Content-Range: bytes {}-{}/{}\r\n", shown_first, shown_last, bytes.size()),
          length))
    return false;
  if (request.method == "HEAD") return true;
  if (reply.kind == RangeReply::Kind::kTruncate) {
    sendAll(fd, bytes.data() + first, length / 2);
    return false;  // closes the connection mid-body
  }
  if (reply.kind == RangeReply::Kind::kStall) {
    sendAll(fd, bytes.data() + first, length / 2);
    lock.lock();
    stalled_ = true;
    changed_.notify_all();
    lock.unlock();
    // Nothing more until the client closes the connection (or the server stops).
    for (;;) {
      pollfd item{fd, POLLIN | POLLRDHUP, 0};
      const int ready = ::poll(&item, 1, 100);
      lock.lock();
      const bool stopping = stopping_;
      lock.unlock();
      if (stopping) return false;
      if (ready > 0) {
        char drop[256];
        if (::recv(fd, drop, sizeof(drop), 0) <= 0) return false;
      }
    }
  }
  return sendAll(fd, bytes.data() + first, length);
}

}  // namespace tessera::test
