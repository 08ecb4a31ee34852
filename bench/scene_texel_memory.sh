#!/usr/bin/env bash
# Texel memory at rest and untextured frames on the real FlightGear scene (issue 28's targets:
# texel memory at rest at most 25 % of every texture at full resolution, with PSNR at rest at
# least 40 dB against the all-resident reference; 0 frames with a visible object untextured
# during every flight). Runs on llvmpipe.
#
#   bench/scene_texel_memory.sh                   # builds the scene, then flies three paths
#   bench/scene_texel_memory.sh --scene sf.tess   # an archive built before
#
# The scene is the one tests/scene/real_scene_test.cpp builds from Debian's
# flightgear-data-models (fetched into build/scene-data, or TESSERA_FGDATA): the script runs
# that test with TESSERA_KEEP_SCENE to keep its archive. Then `tessera fly` flies the built-in
# orbit, a low pass along a row of placements and four jumps to placements (path files
# written here from the test's placement grid), each ending at rest, where the picture is
# compared with every texture resident. One line per flight; each flight's summary.json and frames.csv stay in
# $WORK/<path>/.
set -euo pipefail

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
WORK=${TESSERA_BENCH_DIR:-/tmp/tessera-scene-texels}
TESSERA=${TESSERA:-$REPO/build/src/tools/tessera}
SCENE=""
VIEWPORT=640x360
FPS=30

while [[ $# -gt 0 ]]; do
  case $1 in
    --scene) SCENE=$2; shift 2 ;;
    --viewport) VIEWPORT=$2; shift 2 ;;
    --fps) FPS=$2; shift 2 ;;
    *) echo "usage: $0 [--scene FILE.tess] [--viewport WxH] [--fps N]" >&2; exit 2 ;;
  esac
done

mkdir -p "$WORK"
if [[ -z $SCENE ]]; then
  SCENE=$WORK/sf.tess
  TESSERA_KEEP_SCENE=$SCENE "$REPO/build/tests/scene/tessera_scene_real_data_tests" \
    --gtest_filter='RealScene.*' > "$WORK/build.log"
  [[ -f $SCENE ]] || { echo "the real-data test kept no archive; see $WORK/build.log" >&2; exit 1; }
fi

fly() {  # NAME PATH [extra fly options]
  local name=$1 path=$2
  shift 2
  "$TESSERA" fly "$SCENE" --path "$path" --viewport "$VIEWPORT" --fps "$FPS" -o "$WORK/$name" \
    -q "$@" || true  # exit code 4 (untextured frames, failed reads) is reported below
  python3 - "$name" "$WORK/$name/summary.json" "$(cut -d' ' -f1-3 /proc/loadavg)" <<'EOF'
import json, sys
name, path, load = sys.argv[1], sys.argv[2], sys.argv[3]
s = json.load(open(path))
r = s["rest"]
print(f"{name:9} frames {s['frames']:4} ({s['slowdown']:.2f}x real time)  "
      f"untextured frames {s['untextured_frames']}  "
      f"rest: PSNR {s['scene_rest_psnr_db']:.1f} dB, texels {r['texel_bytes'] / 2**20:.1f} MiB = "
      f"{s['rest_texel_memory_pct']:.1f} % of level 0 ({100 * r['texel_bytes'] / r['full_texel_bytes']:.1f} % "
      f"of every level), peak {s['peak_texel_bytes'] / 2**20:.1f} MiB  "
      f"update p99 {s['update_ms']['p99']:.2f} ms  render p50 {s['render_ms']['p50']:.0f} ms  "
      f"read {s['bytes_read'] / 2**20:.1f} MiB  load {load}")
EOF
}

fly orbit orbit --duration 20
# The real-data test places its models on a grid, column c at longitude -122.40 + 0.004 c and
# row r at latitude 37.62 + 0.004 r, 5 to 11 m up, on a tangent plane at the first one (x east,
# y up, z south): about 352 m between columns along +x and 445 m between rows along -z.
python3 - "$WORK" <<'EOF'
import sys
work = sys.argv[1]
dx, dz = 352.0, -445.0
with open(work + "/low-pass.path", "w") as f:
    # East along row 2, 40 m up and 40 m south of it, looking 20 degrees down; stops halfway
    # and at the end, with placements still ahead.
    z = 2 * dz + 40
    f.write("# t x y z yaw_deg pitch_deg\n")
    f.write(f"0 -100 40 {z} 90 -20\n12 {13 * dx} 40 {z} 90 -20\n")
    f.write(f"17 {13 * dx} 40 {z} 90 -20\n29 {26 * dx} 40 {z} 90 -20\n")
    f.write(f"34 {26 * dx} 40 {z} 90 -20\n")
with open(work + "/jumps.path", "w") as f:
    # Four teleports to 60 m south of a placement and 50 m up, looking at it; 5 s each.
    f.write("# t x y z look tx ty tz [jump]\n")
    t = 0
    for c, r in ((5, 3), (20, 7), (12, 12), (27, 1)):
        x, z = c * dx, r * dz
        line = f"{x} 50 {z + 60} look {x} 5 {z}"
        f.write(f"{t} {line}{' jump' if t else ''}\n{t + 5} {line}\n")
        t += 5
EOF
fly low-pass "$WORK/low-pass.path"
fly jumps "$WORK/jumps.path"
