// `tessera serve`: serves archives over HTTP (or HTTPS) until SIGINT or SIGTERM; SIGHUP reloads
// the TLS certificate (docs/serve.md).
#include <signal.h>
#include <sys/stat.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <memory>

#include <fmt/format.h>

#include <tessera/serve.h>

#include "cli.h"

namespace tessera::cli {

namespace {

/// Every local path exists and is a file or a folder; else an error naming the path and the
/// reason ("No such file or directory", "Permission denied"), before the server starts. An
/// s3:// URL is checked when the server opens it.
Result<void> checkServedPaths(const std::vector<std::string>& paths) {
  for (const std::string& path : paths) {
    if (path.rfind("s3://", 0) == 0) continue;
    struct stat status {};
    if (::stat(path.c_str(), &status) != 0) {
      const int error = errno;
      return fail(error == ENOENT ? ErrorCode::kNotFound : ErrorCode::kIo,
                  fmt::format("{}: cannot serve it: {}", path, std::strerror(error)));
    }
    if (!S_ISDIR(status.st_mode) && !S_ISREG(status.st_mode))
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}: cannot serve it: neither an archive file nor a folder", path));
  }
  return {};
}

int runServe(const ServeOptions& options, double cache_mib, uint32_t port_number) {
  if (Result<void> paths = checkServedPaths(options.paths); !paths)
    return reportError(paths.error());
  ServeOptions resolved = options;
  resolved.port = uint16_t(port_number);
  resolved.transcode_cache_bytes = uint64_t(cache_mib * 1024 * 1024);
  // Block the stop signals before any server thread exists, so every thread inherits the
  // mask and only sigwait below sees them.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  const char* scheme = resolved.tls_cert_file.empty() ? "http" : "https";
  resolved.on_listening = [scheme](const std::string& address, uint16_t port) {
    const bool v6 = address.find(':') != std::string::npos;
    // The first line on stdout, flushed: scripts and tests read the port from it.
    std::printf("listening on %s://%s%s%s:%u\n", scheme, v6 ? "[" : "", address.c_str(),
                v6 ? "]" : "", unsigned(port));
    std::fflush(stdout);
  };
  Result<std::unique_ptr<TileServer>> started = TileServer::start(resolved);
  if (!started) return reportError(started.error());
  TileServer& server = **started;
  std::fprintf(stderr, "tessera serve: %zu archive(s):", server.archiveNames().size());
  for (const std::string& name : server.archiveNames()) std::fprintf(stderr, " %s", name.c_str());
  std::fprintf(stderr, "\n");

  int received = 0;
  while (sigwait(&signals, &received) == 0 && received == SIGHUP) {
    if (!server.tls()) {
      std::fprintf(stderr, "tessera serve: SIGHUP ignored: not serving TLS\n");
    } else if (Result<void> reloaded = server.reloadTls(); !reloaded) {
      std::fprintf(stderr, "tessera serve: SIGHUP: keeping the previous certificate: %s\n",
                   reloaded.error().message.c_str());
    } else {
      std::fprintf(stderr, "tessera serve: SIGHUP: reloaded %s and %s\n",
                   resolved.tls_cert_file.c_str(), resolved.tls_key_file.c_str());
    }
  }
  std::fprintf(stderr, "tessera serve: %s, finishing responses in flight\n",
               received == SIGINT ? "SIGINT" : "SIGTERM");
  server.stop();
  const ServeStats stats = server.stats();
  std::fprintf(stderr, "tessera serve: %llu requests, %s sent, %llu connections\n",
               static_cast<unsigned long long>(stats.requests),
               formatBytes(stats.body_bytes_sent).c_str(),
               static_cast<unsigned long long>(stats.connections_accepted));
  return kExitOk;
}

}  // namespace

void registerServeCommand(CLI::App& app, int& exit_code) {
  auto options = std::make_shared<ServeOptions>();
  auto cache_mib = std::make_shared<double>(64);
  // Read wider than the uint16_t it becomes, so 99999 is "out of range", not "Could not convert".
  auto port = std::make_shared<uint32_t>(options->port);
  CLI::App* cmd = app.add_subcommand(
      "serve",
      "Serve archives over HTTP: tiles, byte ranges, Deep Zoom, XYZ, metrics and the web viewer "
      "(docs/serve.md)");
  cmd->add_option("paths", options->paths,
                  "Archives (.tess), folders of them, or s3:// URLs of archives")
      ->required();
  cmd->add_option("--bind", options->bind_address, "Address to listen on")->capture_default_str();
  cmd->add_option("--port", *port, "TCP port, 0..65535; 0 picks a free one")
      ->capture_default_str()
      ->check(CLI::Range(0u, 65535u));
  cmd->add_option("--threads", options->threads, "I/O threads, 0..1024; 0 = one per core")
      ->capture_default_str()
      ->check(CLI::Range(0u, 1024u));
  cmd->add_option("--max-connections", options->max_connections,
                  "Connections beyond this are closed on accept")
      ->capture_default_str()
      ->check(CLI::Range(1u, 1000000u));
  cmd->add_option("--header-timeout-ms", options->header_timeout_ms,
                  "From a request's first byte to its complete header")
      ->capture_default_str()
      ->check(CLI::Range(1u, 3600000u));
  cmd->add_option("--body-timeout-ms", options->body_timeout_ms, "To receive a request body")
      ->capture_default_str()
      ->check(CLI::Range(1u, 3600000u));
  cmd->add_option("--idle-timeout-ms", options->idle_timeout_ms,
                  "A kept-alive connection waiting for its next request")
      ->capture_default_str()
      ->check(CLI::Range(1u, 3600000u));
  cmd->add_option("--send-timeout-ms", options->send_timeout_ms,
                  "A response write making no progress (client not reading)")
      ->capture_default_str()
      ->check(CLI::Range(1u, 3600000u));
  cmd->add_option("--header-limit", options->header_limit_bytes,
                  "Request line and header bytes (431 beyond)")
      ->capture_default_str()
      ->check(CLI::Range(256u, 1u << 20));
  cmd->add_option("--body-limit", options->body_limit_bytes, "Request body bytes (413 beyond)")
      ->capture_default_str()
      ->check(CLI::Range(0u, 1u << 26));
  cmd->add_option("--max-ranges", options->max_ranges, "Byte ranges per request (416 beyond)")
      ->capture_default_str()
      ->check(CLI::Range(1u, 1000u));
  cmd->add_option("--cache-mib", *cache_mib, "Transcoded-tile cache budget in MiB")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1048576.0));
  cmd->add_option("--jpeg-quality", options->jpeg_quality, "Quality of transcoded JPEG tiles")
      ->capture_default_str()
      ->check(CLI::Range(1, 100));
  cmd->add_option("--cors", options->cors_origin,
                  "Send Access-Control-Allow-Origin with this origin (or *)");
  cmd->add_option("--access-log", options->access_log,
                  "One line per request to FILE, or - for stdout (after the listening line)");
  cmd->add_option("--access", options->access_file,
                  "Access file (JSON): public archives, bearer tokens, URL-signing keys, CORS "
                  "origins and rate limits (docs/serve.md, \"Access control\")")
      ->check(CLI::ExistingFile);
  CLI::Option* tls_cert = cmd->add_option(
      "--tls-cert", options->tls_cert_file,
      "Serve HTTPS with this certificate chain (PEM; reloaded on SIGHUP with the key)");
  CLI::Option* tls_key =
      cmd->add_option("--tls-key", options->tls_key_file, "The certificate's private key (PEM)");
  tls_cert->needs(tls_key);
  tls_key->needs(tls_cert);
  cmd->callback([=, &exit_code] { exit_code = runServe(*options, *cache_mib, *port); });
}

namespace {

struct SignArgs {
  std::string access_file, key, path, archive, range, base;
  int64_t expires_in_s = 3600;
};

int runSign(const SignArgs& args) {
  if (args.path.empty() == args.archive.empty()) {
    std::fprintf(stderr, "tessera sign: give exactly one of --path and --archive\n");
    return kExitUsage;
  }
  const int64_t now = std::chrono::duration_cast<std::chrono::seconds>(
                          std::chrono::system_clock::now().time_since_epoch())
                          .count();
  const std::string scope = args.path.empty() ? "archive:" + args.archive : args.path;
  Result<std::string> query =
      signServeQuery(args.access_file, args.key, scope, now + args.expires_in_s, args.range);
  if (!query) return reportError(query.error());
  // An archive-wide signature works on any of its routes; its archive file is the example.
  const std::string path = args.path.empty() ? "/" + args.archive + ".tess" : args.path;
  std::printf("%s%s?%s\n", args.base.c_str(), path.c_str(), query->c_str());
  return kExitOk;
}

}  // namespace

void registerSignCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<SignArgs>();
  CLI::App* cmd = app.add_subcommand(
      "sign", "Print a time-limited signed URL that `tessera serve --access FILE` accepts");
  cmd->add_option("access", args->access_file, "The server's access file")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--key", args->key, "Signing key id (signing_keys[].id)")->required();
  cmd->add_option("--path", args->path, "One request path, e.g. /earth.tess");
  cmd->add_option("--archive", args->archive, "Every route of this archive instead");
  cmd->add_option("--range", args->range, "Only byte ranges inside FIRST-LAST");
  cmd->add_option("--expires-in", args->expires_in_s, "Seconds from now")
      ->capture_default_str()
      ->check(CLI::Range(int64_t(1), int64_t(10) * 365 * 24 * 3600));
  cmd->add_option("--base", args->base, "Prefix of the printed URL, e.g. https://tiles.example");
  cmd->callback([=, &exit_code] { exit_code = runSign(*args); });
}

}  // namespace tessera::cli
