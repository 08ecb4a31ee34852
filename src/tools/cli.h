#pragma once
// Shared pieces of the `tessera` subcommands: each subcommand file registers its options on
// the CLI11 app and runs; they share only these plain structs and free functions.

#include <cstdint>
#include <cstdio>
#include <string>
#include <string_view>
#include <vector>

#include <CLI/CLI.hpp>

#include <tessera/result.h>

namespace tessera::cli {

/// Exit codes, documented in `tessera --help` and docs/cli.md.
enum ExitCode : int {
  kExitOk = 0,
  kExitFailure = 1,       ///< the operation failed (bad input, I/O error)
  kExitUsage = 2,         ///< bad command line
  kExitCorrupt = 3,       ///< verify found faults
  kExitCancelled = 130,   ///< interrupted by SIGINT (128 + 2)
  kExitTerminated = 143,  ///< stopped by SIGTERM (128 + 15)
};
/// `fly`: the flight ran and wrote its outputs, but tiles failed to load (docs/fly.md).
inline constexpr int kExitLoadFailures = 4;

/// Prints "tessera: <message>" to stderr and returns the exit code for the error.
int reportError(const Error& error);

/// True when stderr is a terminal (progress bars only then).
bool stderrIsTerminal();

/// A one-line progress bar with percentage, throughput and ETA, redrawn in place on stderr.
/// Owned by one thread.
class ProgressBar {
 public:
  explicit ProgressBar(std::string label) : label_(std::move(label)) {}
  /// `done` and `total` in `unit`s; `rate_unit` e.g. "MP/s".
  void update(double done, double total, double elapsed_s, double rate_scale,
              const char* rate_unit);
  void finish();

 private:
  std::string label_;
  bool drawn_ = false;
};

/// Help text of every subcommand's archive argument.
inline constexpr const char* kArchiveArgumentHelp =
    "Archive: a .tess file, an http:// or https:// URL of one on a server that honours "
    "byte ranges, or an s3://BUCKET/KEY URL (docs/remote.md)";

/// Formats a byte count as "12.3 MiB".
std::string formatBytes(uint64_t bytes);

/// Parses a size such as "8GiB", "512M", "1.5g" or "4000000000": a number, then optionally
/// K, M, G, T (powers of 1024, with or without "iB") or KB, MB, GB, TB (powers of 1000); case
/// does not matter. Fails with kInvalidArgument naming `option`, the text and the accepted
/// forms; a size of 0 or past 2^63 bytes is refused.
[[nodiscard]] Result<uint64_t> parseByteSize(const std::string& option, const std::string& text);

/// The name among `candidates` nearest to `word` by edit distance, or "" when none is within
/// a third of the word's length (at least 2 edits): the suggestion for a misspelt name.
std::string nearestName(std::string_view word, const std::vector<std::string>& candidates);

/// Parses a strict "WxH" viewport: digits only on both sides, each side 1..16384.
bool parseViewport(const std::string& text, uint32_t& w, uint32_t& h);

/// Checks an `--egress` value (parseEgressBudget) as CLI11 parses the command line, so a
/// wrong one is a usage error before anything opens.
CLI::Validator egressSpecValidator();

/// "a, b or c": the accepted values of an option, for its "unknown value" message.
std::string listChoices(const std::vector<std::string>& choices);

void registerBuildCommand(CLI::App& app, int& exit_code);
void registerInfoCommand(CLI::App& app, int& exit_code);
void registerVerifyCommand(CLI::App& app, int& exit_code);
void registerMergeCommand(CLI::App& app, int& exit_code);
void registerExtractCommand(CLI::App& app, int& exit_code);
void registerFlyCommand(CLI::App& app, int& exit_code);
void registerViewCommand(CLI::App& app, int& exit_code);
void registerDemoCommand(CLI::App& app, int& exit_code);
void registerRenderCommand(CLI::App& app, int& exit_code);
void registerServeCommand(CLI::App& app, int& exit_code);
void registerSignCommand(CLI::App& app, int& exit_code);
void registerExportCommand(CLI::App& app, int& exit_code);
/// `update`, `append` and `compact` (docs/update.md).
void registerUpdateCommands(CLI::App& app, int& exit_code);

}  // namespace tessera::cli
