// `tessera`: build, inspect, verify and extract texture archives.
#include <CLI/CLI.hpp>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <exception>
#include <new>

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

Result<uint64_t> parseByteSize(const std::string& option, const std::string& text) {
  auto refuse = [&] {
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{} '{}': expected a size such as 512M, 8GiB, 1.5g or 4000000000 "
                            "(K, M, G, T and KiB, MiB, GiB, TiB are powers of 1024; KB, MB, GB, "
                            "TB powers of 1000; above 0)",
                            option, text));
  };
  size_t end = 0;
  while (end < text.size() && (std::isdigit(uint8_t(text[end])) || text[end] == '.')) ++end;
  if (end == 0) return refuse();
  double number = 0;
  try {
    size_t used = 0;
    number = std::stod(text.substr(0, end), &used);
    if (used != end) return refuse();
  } catch (const std::exception&) {
    return refuse();
  }
  std::string unit = text.substr(end);
  std::transform(unit.begin(), unit.end(), unit.begin(),
                 [](char c) { return char(std::tolower(c)); });
  static const struct {
    const char* suffix;
    double scale;
  } kUnits[] = {{"", 1},       {"b", 1},        {"k", 0x1p10},   {"kib", 0x1p10}, {"kb", 1e3},
                {"m", 0x1p20}, {"mib", 0x1p20}, {"mb", 1e6},     {"g", 0x1p30},   {"gib", 0x1p30},
                {"gb", 1e9},   {"t", 0x1p40},   {"tib", 0x1p40}, {"tb", 1e12}};
  for (const auto& u : kUnits) {
    if (unit != u.suffix) continue;
    const double bytes = std::floor(number * u.scale);
    if (!(bytes >= 1) || bytes >= 0x1p63) return refuse();
    return uint64_t(bytes);
  }
  return refuse();
}

std::string nearestName(std::string_view word, const std::vector<std::string>& candidates) {
  // Levenshtein distance with one row; transposed letters count two edits ("biuld" -> "build").
  auto distance = [](std::string_view a, std::string_view b) {
    std::vector<size_t> row(b.size() + 1);
    for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
    for (size_t i = 1; i <= a.size(); ++i) {
      size_t diagonal = row[0];
      row[0] = i;
      for (size_t j = 1; j <= b.size(); ++j) {
        const size_t above = row[j];
        row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
        diagonal = above;
      }
    }
    return row[b.size()];
  };
  std::string best;
  size_t best_distance = std::max<size_t>(2, word.size() / 3) + 1;
  for (const std::string& candidate : candidates) {
    const size_t d = distance(word, candidate);
    if (d < best_distance) {
      best_distance = d;
      best = candidate;
    }
  }
  return best;
}

std::string listChoices(const std::vector<std::string>& choices) {
  std::string out;
  for (size_t i = 0; i < choices.size(); ++i) {
    if (i > 0) out += i + 1 == choices.size() ? " or " : ", ";
    out += choices[i];
  }
  return out;
}

namespace {

/// When the first argument names no subcommand, says so with the nearest one and the list, and
/// returns true (the caller exits 2). CLI11 alone would say only "A subcommand is required".
bool reportUnknownSubcommand(const CLI::App& app, int argc, char** argv) {
  if (argc < 2 || argv[1][0] == '-') return false;
  std::vector<std::string> names;
  for (const CLI::App* sub : app.get_subcommands([](const CLI::App*) { return true; }))
    names.push_back(sub->get_name());
  const std::string word = argv[1];
  if (std::find(names.begin(), names.end(), word) != names.end()) return false;
  const std::string nearest = nearestName(word, names);
  std::fprintf(stderr, "tessera: unknown subcommand '%s'%s; it must be one of %s\n", word.c_str(),
               nearest.empty() ? "" : fmt::format(" (did you mean '{}'?)", nearest).c_str(),
               listChoices(names).c_str());
  return true;
}

}  // namespace

}  // namespace tessera::cli

int main(int argc, char** argv) {
  using namespace tessera::cli;
  CLI::App app{
      "tessera: streams textures far larger than memory.\n"
      "Exit codes: 0 success, 1 failure, 2 usage error (a bad option or value), 3 verify found "
      "faults, 4 fly or demo: tiles failed to load, 130 interrupted by SIGINT, 143 stopped by "
      "SIGTERM (docs/cli.md)."};
  app.require_subcommand(1);
  app.set_version_flag("--version", "tessera 0.1.0 (archive format 1.0)");
  int exit_code = kExitOk;
  registerBuildCommand(app, exit_code);
  registerInfoCommand(app, exit_code);
  registerVerifyCommand(app, exit_code);
  registerMergeCommand(app, exit_code);
  registerExtractCommand(app, exit_code);
  registerFlyCommand(app, exit_code);
  registerDemoCommand(app, exit_code);
  registerViewCommand(app, exit_code);
  registerRenderCommand(app, exit_code);
  registerServeCommand(app, exit_code);
  registerSignCommand(app, exit_code);
  registerBrushesCommand(app, exit_code);
  registerExportCommand(app, exit_code);
  registerUpdateCommands(app, exit_code);
  if (reportUnknownSubcommand(app, argc, argv)) return kExitUsage;
  // The subcommands run inside parse: whatever escapes them (an allocation the estimates did
  // not foresee, a library's exception) ends here as one line and exit 1, never an abort.
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    int code = app.exit(e);
    return code == 0 ? 0 : kExitUsage;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr,
                 "tessera: out of memory (a build's --memory-limit bounds what it asks "
                 "for; docs/builder.md)\n");
    return kExitFailure;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tessera: internal error: %s\n", e.what());
    return kExitFailure;
  } catch (...) {
    std::fprintf(stderr, "tessera: internal error: an unknown exception\n");
    return kExitFailure;
  }
  return exit_code;
}
