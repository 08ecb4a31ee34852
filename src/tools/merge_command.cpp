// `tessera merge`: the parts of a split build -> one archive (docs/builder.md).
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <tessera/split_build.h>

#include "cli.h"

namespace tessera::cli {

namespace {

struct MergeArgs {
  std::vector<std::string> parts;
  std::string output;
  bool quiet = false;
  bool json = false;
};

int runMerge(const MergeArgs& args) {
  Result<MergeReport> report = mergeArchiveParts(args.parts, args.output);
  if (!report) return reportError(report.error());
  if (args.json) {
    std::printf("%s\n", nlohmann::json({{"output", args.output},
                                        {"output_bytes", report->output_bytes},
                                        {"payload_bytes_copied", report->payload_bytes_copied},
                                        {"tiles_copied", report->tiles_copied},
                                        {"part_reads", report->part_reads},
                                        {"tiles_computed", report->tiles_computed},
                                        {"elapsed_s", report->elapsed_s},
                                        {"open_s", report->open_s},
                                        {"coarse_s", report->coarse_s},
                                        {"copy_s", report->copy_s},
                                        {"commit_s", report->commit_s}})
                            .dump(2)
                            .c_str());
  } else if (!args.quiet) {
    std::printf("%s: %zu parts, %s in %.2f s; %llu tiles copied, %llu computed\n",
                args.output.c_str(), args.parts.size(), formatBytes(report->output_bytes).c_str(),
                report->elapsed_s, (unsigned long long)report->tiles_copied,
                (unsigned long long)report->tiles_computed);
  }
  return kExitOk;
}

}  // namespace

void registerMergeCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<MergeArgs>();
  CLI::App* cmd = app.add_subcommand(
      "merge", "Join the parts of a split build (tessera build --part I/N) into one archive");
  cmd->add_option("parts", args->parts, "Every part archive of the build, in any order")
      ->required();
  cmd->add_option("-o,--output", args->output, "Archive to write (atomically)")->required();
  cmd->add_flag("-q,--quiet", args->quiet, "No summary");
  cmd->add_flag("--json", args->json, "Print the merge report as JSON");
  cmd->callback([args, &exit_code] { exit_code = runMerge(*args); });
}

}  // namespace tessera::cli
