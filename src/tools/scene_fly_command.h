#pragma once
// `tessera fly SCENE.tess`: a camera path through a 3D scene, streamed by SceneStreamer and
// drawn headless by SceneRenderer, with the image flights' outputs (docs/fly.md, "Scenes").

#include <string>

#include "fly_command.h"

namespace tessera::cli {

/// True when the local file `path_or_url` opens as a scene archive (a 1.1 archive with a scene
/// section): the fly and view commands then take the scene path. False for anything else,
/// URLs and errors included (the image path reports them).
bool isSceneArchive(const std::string& path_or_url);

/// Flies a scene: `args.path` is "orbit" (also what the image default "pan" means here) or a
/// scene keyframe file; --duration, --viewport, --fps, --threads (the streamer's workers),
/// --upload-budget-mib, --screenshots, --report, --json, --quiet and -o apply. Writes
/// frames.csv, summary.json, rest.png and reference.png (and report.html) to `args.out_dir`.
/// Returns the exit code, having printed any error: 4 when reads failed or a visible object
/// was ever drawn untextured after the first picture.
int runSceneFly(const FlyArgs& args);

}  // namespace tessera::cli
