#!/usr/bin/env bash
# The main job: installs the Debian packages, builds Tessera (Release) into build/, builds a
# multi-gigapixel archive from the synthetic source and prints its summary. The archive is
# rebuilt only when it is missing, was built with other parameters, or is older than the
# `tessera` binary.
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

mkdir -p "$out_dir"
archive=$out_dir/synthetic-$size.tess
args=(build "synthetic:$size" -o "$archive" --tile 256 --codec jpeg --quality 85)
stamp=$archive.args  # the arguments the archive was built with
if [[ -f $archive && -f $stamp && $archive -nt $tessera && $(<"$stamp") == "${args[*]}" ]]; then
  echo "demo: $archive is up to date"
else
  echo "demo: tessera ${args[*]}"
  rm -f "$stamp"
  "$tessera" "${args[@]}"
  printf '%s\n' "${args[*]}" >"$stamp"
fi

echo
"$tessera" info "$archive"
