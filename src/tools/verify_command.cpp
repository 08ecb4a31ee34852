// `tessera verify`: every checksum and structural invariant.
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <tessera/archive.h>
#include <tessera/open.h>
#include <tessera/scene.h>

#include "cli.h"

namespace tessera::cli {

namespace {

// The scene half (docs/scenes.md): a scene archive's tree, meshes and texture table, its
// faults added to the 1.0 checks' report. Nothing for an archive without a scene.
void verifySceneInto(const std::string& path, const Archive& archive, bool decode,
                     VerifyReport& report, uint64_t* nodes_checked, uint64_t* hint_cells) {
  Result<std::shared_ptr<ByteSource>> source = openByteSource(path);
  if (!source) return;
  Result<std::shared_ptr<SceneArchive>> scene = SceneArchive::open(*source);
  if (!scene) {
    if (scene.error().code == ErrorCode::kNotFound) return;
    ++report.fault_count;
    report.faults.push_back(scene.error().message);
    return;
  }
  SceneVerifyReport walked = verifyScene(**scene, archive.images(), decode);
  *nodes_checked = walked.nodes_checked;
  *hint_cells = walked.hint_cells_checked;
  report.fault_count += walked.fault_count;
  report.faults.insert(report.faults.end(), walked.faults.begin(), walked.faults.end());
}

int runVerify(const std::string& path, bool json, bool decode, bool quiet) {
  Result<std::shared_ptr<Archive>> opened = openArchive(path);
  if (!opened) {
    if (json)
      std::printf("%s\n", nlohmann::json({{"path", path},
                                          {"ok", false},
                                          {"fault_count", 1},
                                          {"faults", {opened.error().message}}})
                              .dump(2)
                              .c_str());
    int code = reportError(opened.error());
    return opened.error().code == ErrorCode::kCorrupt ? int(kExitCorrupt) : code;
  }
  bool show_progress = !quiet && !json && stderrIsTerminal();
  ProgressBar bar("verifying");
  VerifyReport report = (*opened)->verify(decode, [&](uint64_t done, uint64_t total) {
    if (show_progress) bar.update(double(done), double(total), 0, 1, "levels");
  });
  bar.finish();
  uint64_t scene_nodes = 0, hint_cells = 0;
  verifySceneInto(path, **opened, decode, report, &scene_nodes, &hint_cells);
  if (json) {
    std::printf("%s\n", nlohmann::json({{"path", path},
                                        {"ok", report.ok()},
                                        {"fault_count", report.fault_count},
                                        {"faults", report.faults},
                                        {"tiles_checked", report.tiles_checked},
                                        {"payloads_checked", report.payloads_checked},
                                        {"payload_bytes", report.payload_bytes},
                                        {"pages_checked", report.pages_checked},
                                        {"scene_nodes_checked", scene_nodes},
                                        {"coverage_hint_cells_checked", hint_cells}})
                            .dump(2)
                            .c_str());
  } else {
    for (const std::string& fault : report.faults) std::fprintf(stderr, "%s\n", fault.c_str());
    if (report.fault_count > report.faults.size())
      std::fprintf(stderr, "... and %llu more\n",
                   (unsigned long long)(report.fault_count - report.faults.size()));
    if (report.ok()) {
      if (!quiet)
        std::printf(
            "%s: OK (%llu tiles, %llu payloads, %s, %llu directory pages%s)\n", path.c_str(),
            (unsigned long long)report.tiles_checked, (unsigned long long)report.payloads_checked,
            formatBytes(report.payload_bytes).c_str(), (unsigned long long)report.pages_checked,
            scene_nodes
                ? fmt::format(", {} scene nodes{}", scene_nodes,
                              hint_cells ? fmt::format(", {} coverage hint cells", hint_cells) : "")
                      .c_str()
                : "");
    } else {
      std::printf("%s: %llu fault(s); first: %s\n", path.c_str(),
                  (unsigned long long)report.fault_count, report.faults.front().c_str());
    }
  }
  return report.ok() ? kExitOk : kExitCorrupt;
}

}  // namespace

void registerVerifyCommand(CLI::App& app, int& exit_code) {
  auto path = std::make_shared<std::string>();
  auto json = std::make_shared<bool>(false);
  auto no_decode = std::make_shared<bool>(false);
  auto quiet = std::make_shared<bool>(false);
  CLI::App* cmd = app.add_subcommand(
      "verify", "Check every checksum and structural invariant; exit 3 on faults");
  cmd->add_option("archive", *path, kArchiveArgumentHelp)->required();
  cmd->add_flag("--json", *json, "Machine-readable report");
  cmd->add_flag("--no-decode", *no_decode, "Check checksums only, do not decode payloads");
  cmd->add_flag("-q,--quiet", *quiet, "Print only faults");
  cmd->callback([=, &exit_code] { exit_code = runVerify(*path, *json, !*no_decode, *quiet); });
}

}  // namespace tessera::cli
