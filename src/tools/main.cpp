// `tessera`: build, inspect, verify and extract texture archives.
#include <CLI/CLI.hpp>

#include <unistd.h>

#include <fmt/format.h>

#include <tessera/byte_source.h>
#include <tessera/stream.h>

#include "cli.h"
#include "procedural_cli.h"

namespace tessera::cli {

int reportError(const Error& error) {
  std::fprintf(stderr, "tessera: %s\n", error.message.c_str());
  if (error.code == ErrorCode::kCancelled) return kExitCancelled;
  if (error.code == ErrorCode::kInvalidArgument) return kExitUsage;
  return kExitFailure;
}

bool stderrIsTerminal() {
  return ::isatty(STDERR_FILENO) == 1;
}

std::string formatBytes(uint64_t bytes) {
  const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB"};
  double value = double(bytes);
  int unit = 0;
  while (value >= 1024 && unit < 4) {
    value /= 1024;
    ++unit;
  }
  return unit == 0 ? fmt::format("{} B", bytes) : fmt::format("{:.1f} {}", value, units[unit]);
}

void ProgressBar::update(double done, double total, double elapsed_s, double rate_scale,
                         const char* rate_unit) {
  double fraction = total > 0 ? std::min(1.0, done / total) : 0;
  constexpr int kWidth = 30;
  int filled = int(fraction * kWidth);
  std::string bar(size_t(filled), '#');
  bar.resize(kWidth, '.');
  double rate = elapsed_s > 0 ? done / rate_scale / elapsed_s : 0;
  std::string eta = "--:--";
  if (fraction > 0.001 && fraction < 1) {
    int seconds = int(elapsed_s * (1 / fraction - 1));
    eta = fmt::format("{:02d}:{:02d}", seconds / 60, seconds % 60);
  }
  std::fprintf(stderr, "\r%s [%s] %5.1f%%  %.1f %s  ETA %s ", label_.c_str(), bar.c_str(),
               fraction * 100, rate, rate_unit, eta.c_str());
  std::fflush(stderr);
  drawn_ = true;
}

void ProgressBar::finish() {
  if (drawn_) std::fprintf(stderr, "\n");
  drawn_ = false;
}

}  // namespace tessera::cli

int main(int argc, char** argv) {
  using namespace tessera::cli;
  CLI::App app{
      "tessera: streams textures far larger than memory.\n"
      "Exit codes: 0 success, 1 failure, 2 usage error, 3 verify found faults, 130 interrupted."};
  app.require_subcommand(1);
  app.set_version_flag("--version", "tessera 0.1.0 (archive format 1.0)");
  int exit_code = kExitOk;
  registerBuildCommand(app, exit_code);
  registerInfoCommand(app, exit_code);
  registerVerifyCommand(app, exit_code);
  registerExtractCommand(app, exit_code);
  registerFlyCommand(app, exit_code);
  registerDemoCommand(app, exit_code);
  registerViewCommand(app, exit_code);
  registerRenderCommand(app, exit_code);
  registerServeCommand(app, exit_code);
  registerBrushesCommand(app, exit_code);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    int code = app.exit(e);
    return code == 0 ? 0 : kExitUsage;
  }
  return exit_code;
}
