#pragma once
// `tessera view SCENE.tess`: the window on a streamed scene (docs/view.md, "Scenes").

#include "view_command.h"

namespace tessera::cli {

/// Opens the window on a scene archive and runs until it closes: walk and fly controls, the
/// level tint and R-tree node overlays (--overlays levels,nodes). --size, --screenshot-dir and
/// --frames apply as for images. Returns the exit code, having printed any error.
int runSceneView(const ViewArgs& args);

}  // namespace tessera::cli
