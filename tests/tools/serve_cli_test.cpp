// `tessera serve` as a real process: the "listening on" first line, a request answered on the
// printed port, and a graceful exit on SIGTERM; start-up errors name the file.
#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <tessera/build.h>

extern char** environ;

namespace tessera {
namespace {

struct Spawned {
  pid_t pid = -1;
  int stdout_fd = -1;
};

// Starts `tessera args...` with stdout on a pipe and stderr into `err_path`.
Spawned spawnTessera(const std::vector<std::string>& args, const std::string& err_path) {
  int fds[2];
  if (::pipe(fds) != 0) return {};
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, fds[1], 1);
  posix_spawn_file_actions_addclose(&actions, fds[0]);
  posix_spawn_file_actions_addopen(&actions, 2, err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC,
                                   0644);
  std::vector<std::string> strings = {TESSERA_CLI_PATH};
  strings.insert(strings.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& s : strings) argv.push_back(s.data());
  argv.push_back(nullptr);
  Spawned spawned;
  int rc = posix_spawn(&spawned.pid, TESSERA_CLI_PATH, &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  ::close(fds[1]);
  if (rc != 0) {
    ::close(fds[0]);
    return {};
  }
  spawned.stdout_fd = fds[0];
  return spawned;
}

// The first line on `fd`, waiting at most 60 s (a guard against a hang, not a delay).
std::string readLine(int fd) {
  std::string line;
  char c = 0;
  while (true) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 60000) <= 0) break;
    if (::read(fd, &c, 1) != 1 || c == '\n') break;
    line += c;
  }
  return line;
}

int waitExit(pid_t pid) {
  int status = 0;
  ::waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string slurp(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

std::string httpGet(uint16_t port, const std::string& target) {
  int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(port);
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  timeval guard{30, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &guard, sizeof guard);
  std::string reply;
  if (::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0) {
    std::string request =
        fmt::format("GET {} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n", target);
    if (::send(fd, request.data(), request.size(), MSG_NOSIGNAL) == ssize_t(request.size())) {
      char chunk[4096];
      ssize_t n;
      while ((n = ::recv(fd, chunk, sizeof chunk, 0)) > 0) reply.append(chunk, size_t(n));
    }
  }
  ::close(fd);
  return reply;
}

std::string testDir() {
  auto dir =
      std::filesystem::path(::testing::TempDir()) / fmt::format("tessera_serve_cli_{}", ::getpid());
  std::filesystem::create_directories(dir);
  return dir.string();
}

TEST(ServeCli, PrintsItsPortServesAndStopsOnSigterm) {
  const std::string dir = testDir();
  BuildOptions options;
  options.inputs = {"synthetic:300x200:1:3"};
  options.output = dir + "/small.tess";
  options.tile_size_px = 64;
  options.codec = Codec::kPng;
  ASSERT_TRUE(buildArchive(options));
  const std::string err = dir + "/serve.stderr";
  Spawned server = spawnTessera({"serve", options.output, "--port", "0", "--threads", "1"}, err);
  ASSERT_GT(server.pid, 0);
  const std::string line = readLine(server.stdout_fd);
  ASSERT_TRUE(line.starts_with("listening on http://127.0.0.1:")) << line;
  const int port = std::stoi(line.substr(line.rfind(':') + 1));
  ASSERT_GT(port, 0);
  std::string health = httpGet(uint16_t(port), "/healthz");
  EXPECT_TRUE(health.starts_with("HTTP/1.1 200")) << health;
  EXPECT_TRUE(health.ends_with("\r\n\r\nok")) << health;
  EXPECT_TRUE(httpGet(uint16_t(port), "/small/info.json").starts_with("HTTP/1.1 200"));
  ::kill(server.pid, SIGTERM);
  EXPECT_EQ(waitExit(server.pid), 0);
  ::close(server.stdout_fd);
  EXPECT_NE(slurp(err).find("2 requests"), std::string::npos) << slurp(err);
  std::filesystem::remove_all(dir);
}

TEST(ServeCli, StartUpErrorsNameTheFile) {
  const std::string dir = testDir();
  const std::string err = dir + "/missing.stderr";
  Spawned server = spawnTessera({"serve", dir + "/missing.tess", "--port", "0"}, err);
  ASSERT_GT(server.pid, 0);
  EXPECT_EQ(readLine(server.stdout_fd), "");  // nothing on stdout: no listening line
  EXPECT_EQ(waitExit(server.pid), 1);
  ::close(server.stdout_fd);
  EXPECT_NE(slurp(err).find(dir + "/missing.tess"), std::string::npos) << slurp(err);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace tessera
