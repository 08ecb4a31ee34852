#pragma once
// `tessera build` and `tessera info` for scene archives (docs/scenes.md): the scene options
// and the two runs, registered from build_command.cpp and info_command.cpp.

#include <atomic>
#include <string>

#include <CLI/CLI.hpp>

#include <tessera/build.h>

namespace tessera::cli {

/// Adds --leaf-capacity, --fan-out, --geometry-codec, --texture-source and --max-texture-side
/// to `build`.
void addSceneBuildOptions(CLI::App& build);
/// True when the build's single input is a scene (isSceneInput).
bool isSceneBuild(const BuildOptions& options);
/// Runs the scene build with the image options `options` carries (tile size, codec, quality,
/// effort, threads) and prints its report; returns the exit code.
int runSceneBuild(const BuildOptions& options, bool quiet, bool json,
                  const std::atomic<bool>* cancel);

/// Adds --tree-depth to `info`.
void addSceneInfoOptions(CLI::App& info);
/// When `path` is a scene archive, prints its scene (tree, promotion statistics, sizes) and
/// sets `exit_code`, returning true; returns false for any other archive.
bool runSceneInfo(const std::string& path, bool json, int* exit_code);

}  // namespace tessera::cli
