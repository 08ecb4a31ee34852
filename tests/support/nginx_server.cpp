#include "support/nginx_server.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>
#include <vector>

#include <fmt/format.h>

extern char** environ;

namespace tessera::test {

namespace {

sockaddr_in loopback(uint16_t port) {
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(port);
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  return address;
}

/// Runs a program to completion, its output to `log`; true when it exited 0.
bool runQuietly(std::vector<std::string> args, const std::string& log) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&actions, 1, 2);
  std::vector<char*> argv;
  for (std::string& arg : args) argv.push_back(arg.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  const int spawned = posix_spawn(&pid, args[0].c_str(), &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  int status = 0;
  return spawned == 0 && ::waitpid(pid, &status, 0) == pid && WIFEXITED(status) &&
         WEXITSTATUS(status) == 0;
}

std::string config(const std::string& root, const std::string& dir, uint16_t port,
                   uint16_t h2c_port, uint16_t tls_port) {
  // Every path nginx writes is inside `dir`: it runs as any user, next to other instances.
  const std::string locations = fmt::format(R"(
    root {0};
    location /noranges/ {{ alias {0}/; max_ranges 0; }}
    location /slow/ {{ alias {0}/; limit_rate 256k; }}
    location /unavailable/ {{ return 503; }}
    location = /status {{ stub_status; }}
)",
                                            root);
  return fmt::format(R"(daemon off;
master_process off;
worker_processes 1;
pid {0}/nginx.pid;
error_log {0}/error.log warn;
events {{ worker_connections 256; }}
http {{
  access_log off;
  client_body_temp_path {0}/body;
  proxy_temp_path {0}/proxy;
  fastcgi_temp_path {0}/fastcgi;
  uwsgi_temp_path {0}/uwsgi;
  scgi_temp_path {0}/scgi;
  default_type application/octet-stream;
  keepalive_requests 100000;
  server {{
    listen 127.0.0.1:{1};
{3}
  }}
  server {{
    listen 127.0.0.1:{2} http2;
{3}
  }}
{4}
}}
)",
                     dir, port, h2c_port, locations,
                     tls_port == 0 ? std::string()
                                   : fmt::format(R"(  server {{
    listen 127.0.0.1:{0} ssl http2;
    ssl_certificate {1}/cert.pem;
    ssl_certificate_key {1}/key.pem;
{2}
  }})",
                                                 tls_port, dir, locations));
}

}  // namespace

uint16_t freeLoopbackPort() {
  int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return 0;
  sockaddr_in address = loopback(0);
  uint16_t port = 0;
  socklen_t length = sizeof(address);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)) == 0 &&
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&address), &length) == 0)
    port = ntohs(address.sin_port);
  ::close(fd);
  return port;
}

bool waitForPort(uint16_t port, pid_t pid) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (std::chrono::steady_clock::now() < deadline) {
    int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in address = loopback(port);
    const bool connected =
        fd >= 0 && ::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)) == 0;
    if (fd >= 0) ::close(fd);
    if (connected) return true;
    int status = 0;
    if (pid > 0 && ::waitpid(pid, &status, WNOHANG) == pid) return false;
    // The polling interval of a readiness probe, not a wait for an event.
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return false;
}

bool NginxServer::available() {
  return ::access(kBinary, X_OK) == 0;
}

Result<std::unique_ptr<NginxServer>> NginxServer::start(const std::string& root,
                                                        const std::string& work_dir) {
  std::error_code ec;
  std::filesystem::create_directories(work_dir, ec);
  const std::string absolute_root = std::filesystem::absolute(root).string();
  const std::string dir = std::filesystem::absolute(work_dir).string();
  std::string last_log;
  const bool tls = ::access("/usr/bin/openssl", X_OK) == 0 &&
                   runQuietly({"/usr/bin/openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes",
                               "-keyout", dir + "/key.pem", "-out", dir + "/cert.pem", "-days", "2",
                               "-subj", "/CN=127.0.0.1", "-addext", "subjectAltName=IP:127.0.0.1"},
                              dir + "/openssl.out");
  // Another process may take a port between our check and nginx's bind: try new ones.
  for (int attempt = 0; attempt < 5; ++attempt) {
    const uint16_t port = freeLoopbackPort(), h2c_port = freeLoopbackPort();
    const uint16_t tls_port = tls ? freeLoopbackPort() : 0;
    if (port == 0 || h2c_port == 0 || port == h2c_port || tls_port == port || tls_port == h2c_port)
      continue;
    const std::string conf = dir + "/nginx.conf";
    std::ofstream(conf) << config(absolute_root, dir, port, h2c_port, tls_port);
    const std::string log = dir + "/nginx.out";
    std::vector<std::string> args = {kBinary, "-p", dir + "/",         "-c",
                                     conf,    "-e", dir + "/error.log"};
    std::vector<char*> argv;
    for (std::string& arg : args) argv.push_back(arg.data());
    argv.push_back(nullptr);
    const pid_t parent = ::getpid();
    // fork + exec rather than posix_spawn, for PR_SET_PDEATHSIG: nginx dies with the test
    // even when the test is killed before its destructor runs. Only async-signal-safe calls
    // between fork and exec.
    const pid_t pid = ::fork();
    if (pid < 0) return fail(ErrorCode::kIo, fmt::format("{}: cannot fork", kBinary));
    if (pid == 0) {
      ::prctl(PR_SET_PDEATHSIG, SIGTERM);
      if (::getppid() != parent) ::_exit(127);
      const int out = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
      if (out >= 0) {
        ::dup2(out, 1);
        ::dup2(out, 2);
      }
      ::execv(kBinary, argv.data());
      ::_exit(127);
    }
    if (waitForPort(port, pid) && waitForPort(h2c_port, pid) &&
        (tls_port == 0 || waitForPort(tls_port, pid)))
      return std::unique_ptr<NginxServer>(new NginxServer(pid, port, h2c_port, tls_port, dir));
    ::kill(pid, SIGTERM);
    ::waitpid(pid, nullptr, 0);
    std::ifstream in(dir + "/error.log");
    std::stringstream text;
    text << in.rdbuf();
    last_log = text.str();
  }
  return fail(ErrorCode::kIo, "nginx did not start: " + last_log);
}

NginxServer::~NginxServer() {
  ::kill(pid_, SIGTERM);
  ::waitpid(pid_, nullptr, 0);
}

std::string NginxServer::url(const std::string& path) const {
  return fmt::format("http://127.0.0.1:{}/{}", port_, path);
}

std::string NginxServer::h2cUrl(const std::string& path) const {
  return fmt::format("http://127.0.0.1:{}/{}", h2c_port_, path);
}

std::string NginxServer::certificateFile() const {
  return tls_port_ ? work_dir_ + "/cert.pem" : std::string();
}

std::string NginxServer::httpsUrl(const std::string& path) const {
  return tls_port_ ? fmt::format("https://127.0.0.1:{}/{}", tls_port_, path) : std::string();
}

Result<uint64_t> NginxServer::acceptedConnections() const {
  int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in address = loopback(port_);
  if (fd < 0 || ::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)) != 0) {
    if (fd >= 0) ::close(fd);
    return fail(ErrorCode::kIo, "cannot connect to nginx");
  }
  const std::string request = "GET /status HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n";
  if (::send(fd, request.data(), request.size(), MSG_NOSIGNAL) != ssize_t(request.size())) {
    ::close(fd);
    return fail(ErrorCode::kIo, "cannot send to nginx");
  }
  std::string reply;
  char buffer[4096];
  for (ssize_t n; (n = ::recv(fd, buffer, sizeof(buffer), 0)) > 0;) reply.append(buffer, size_t(n));
  ::close(fd);
  // "server accepts handled requests\n A H R"
  const size_t at = reply.find("requests");
  unsigned long long accepts = 0;
  if (at == std::string::npos || std::sscanf(reply.c_str() + at + 8, "%llu", &accepts) != 1)
    return fail(ErrorCode::kIo, "unexpected stub_status reply: " + reply);
  return uint64_t(accepts);
}

}  // namespace tessera::test
