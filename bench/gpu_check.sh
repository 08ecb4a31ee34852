#!/usr/bin/env bash
# The GPU check (issue 30, item 5, in part): on any machine with OpenGL 4.5 (a GPU, or Mesa's
# llvmpipe without one) it runs the GL tests, then the standard jump and pan flights at FHD
# and 4K for both renderers, in real time at 60 fps, and writes one table naming the GL
# renderer the flights ran on (summary.json's `gl`), so figures from llvmpipe are never taken
# for a GPU's; then each renderer's still frame against the single-fetch floor at FHD and 4K
# (bench/gpu_floor.cpp), a second table.
#
#   bench/gpu_check.sh                         # 65536^2 archive, 5-s flights
#   bench/gpu_check.sh --size 16384x16384 --seconds 2
#
# Needs a Release build with tests and tools (build/). Each flight's outputs stay in
# $WORK/<renderer>-<viewport>-<path>/; the table is printed and kept in $WORK/gpu_check.md.
set -euo pipefail

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
BUILD=${TESSERA_BUILD:-$REPO/build}
WORK=${TESSERA_BENCH_DIR:-/tmp/tessera-gpu-check}
TESSERA=${TESSERA:-$BUILD/src/tools/tessera}
SIZE=65536x65536
SECONDS_PER_FLIGHT=5
while [[ $# -gt 0 ]]; do
  case $1 in
    --size) SIZE=$2; shift 2 ;;
    --seconds) SECONDS_PER_FLIGHT=$2; shift 2 ;;
    *) echo "gpu_check.sh: unknown option $1" >&2; exit 2 ;;
  esac
done
mkdir -p "$WORK"

echo "gpu_check: GL tests"
ctest --test-dir "$BUILD" -R 'Renderer|Clipmap|TileQuads|RingSpans|GlContext' --output-on-failure

ARCHIVE=$WORK/synthetic-$SIZE.tess
if [[ ! -f $ARCHIVE ]]; then
  echo "gpu_check: building $ARCHIVE"
  "$TESSERA" build "synthetic:$SIZE:2:3" -o "$ARCHIVE" --tile 256 --border 1 --codec jpeg \
    --quality 85 -q
fi

TABLE=$WORK/gpu_check.md
{
  echo "gpu_check $(date -u +%Y-%m-%dT%H:%MZ), Tessera $(git -C "$REPO" rev-parse --short HEAD), load average $(cut -d' ' -f1-3 /proc/loadavg), $SIZE, ${SECONDS_PER_FLIGHT}-s flights at 60 fps"
  echo
  echo "| GL renderer | renderer | viewport | path | wall s | drawn | render p99 ms | GPU p99 ms | full detail % | jumps at full detail | upload budget MiB |"
  echo "|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|"
} > "$TABLE"
for renderer in tile-quads clipmap; do
  for viewport in 1920x1080 3840x2160; do
    for path in jump pan; do
      out=$WORK/$renderer-$viewport-$path
      speed=$([[ $path == pan ]] && echo 20000 || echo 1000)
      "$TESSERA" fly "$ARCHIVE" --path "$path" --speed "$speed" --duration "$SECONDS_PER_FLIGHT" \
        --viewport "$viewport" --fps 60 --render "$renderer" -q --out "$out"
      python3 - "$out/summary.json" "$renderer" "$viewport" "$path" >> "$TABLE" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
jumps = sum(1 for j in s["jumps"] if j["full_detail_ms"] is not None)
print(f"| {s['gl']} | {sys.argv[2]} | {sys.argv[3]} | {sys.argv[4]} | {s['wall_s']:.2f} | "
      f"{s['frames']} | {s['render_ms']['p99']:.1f} | {s['gpu_ms']['p99']:.1f} | "
      f"{s['frames_full_detail_pct']:.1f} | {jumps}/{len(s['jumps'])} | "
      f"{s['upload_budget']['bytes_p50'] / 1048576:.1f} |")
PY
    done
  done
done
{
  echo
  echo "Still frame against the single-fetch floor (tessera-gpu-floor):"
  echo
  "$BUILD/bench/tessera-gpu-floor" "$ARCHIVE" --viewport 1920x1080,3840x2160 \
    --json "$WORK/gpu_floor.json"
} >> "$TABLE"
cat "$TABLE"
