#!/usr/bin/env bash
# The main job: installs the Debian packages, builds Tessera (Release) into build/, and runs
# `tessera demo`: a multi-gigapixel archive from the synthetic source (built once), flown
# headless along the standard paths and drawn by the OpenGL renderer (Mesa's llvmpipe where
# there is no GPU), with an HTML report whose path and headline figures it prints. Arguments
# are passed to `tessera demo` (e.g. --view to open the viewer afterwards, with a display).
#
# Environment (all optional):
#   TESSERA_DEMO_SIZE   synthetic image size WxH, default 65536x65536 (4.3 gigapixels)
#   TESSERA_DEMO_BUILD  build folder, default <repo>/build
#   TESSERA_DEMO_OUT    output folder, default <repo>/out
#   TESSERA_DEMO_JOBS   parallel compile jobs, default $(nproc)
set -euo pipefail

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$repo"
size=${TESSERA_DEMO_SIZE:-65536x65536}
build_dir=${TESSERA_DEMO_BUILD:-$repo/build}
out_dir=${TESSERA_DEMO_OUT:-$repo/out}
jobs=${TESSERA_DEMO_JOBS:-$(nproc)}

scripts/install-deps.sh

echo "demo: building Tessera (Release) in $build_dir"
cmake -S "$repo" -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release -DTESSERA_BUILD_TOOLS=ON
cmake --build "$build_dir" -j "$jobs" --target tessera_cli
tessera=$build_dir/src/tools/tessera

# `tessera demo` builds the sample archive once (rebuilt only when its options change), flies
# the standard paths headless with the tile-quads renderer, and writes $out_dir/demo.html.
"$tessera" demo --dir "$out_dir" --size "$size" "$@"
