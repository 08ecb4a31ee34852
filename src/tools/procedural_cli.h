#pragma once
// The procedural subcommands' entry points for main.cpp and build_command.cpp:
// `tessera brushes ...` (brushes_command.cpp) and `tessera build --procedural DB`
// (procedural_build_command.cpp).

#include <memory>
#include <string>

#include <CLI/CLI.hpp>

#include <tessera/build.h>

namespace tessera::cli {

void registerBrushesCommand(CLI::App& app, int& exit_code);

/// The options `tessera build` gains for mixed archives. Owned by the build subcommand.
struct ProceduralBuildFlags {
  std::string database;  ///< --procedural: empty means an ordinary build
  std::string base;
  double frame_budget_ms = 4.0;
  uint32_t max_new_tiles = 4;
  double small_instance_texels = 0.25;
  double cost_texel_ns = 4.5;
  std::vector<std::string> detail_regions;  ///< "x0,y0,x1,y1:level"
  bool bake_all = false;
  bool requested() const { return !database.empty(); }
};

/// Adds --procedural and its options to the build subcommand.
std::shared_ptr<ProceduralBuildFlags> addProceduralBuildOptions(CLI::App* build);

/// Runs the mixed build with the build subcommand's common options (output, tile, border,
/// codec, quality, effort, threads, order, page size).
int runProceduralBuild(const ProceduralBuildFlags& flags, const BuildOptions& common,
                       const std::string& codec, bool quiet, bool json);

}  // namespace tessera::cli
