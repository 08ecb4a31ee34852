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
# orbit, a low pass along the placements and four jumps (path files written here from the
# scene's bounds), each ending at rest, where the picture is compared with every texture
# resident. One line per flight; each flight's summary.json and frames.csv stay in
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
# Paths from the scene's bounds (summary.json of the orbit): x east, y up, z south.
python3 - "$WORK/orbit/summary.json" "$WORK" <<'EOF'
import json, sys
b = json.load(open(sys.argv[1]))["scene"]["bounds"]
(x0, y0, z0), (x1, y1, z1) = b["min"], b["max"]
cz = (z0 + z1) / 2
with open(sys.argv[2] + "/low-pass.path", "w") as f:
    # East along the middle row 40 m up, looking 25 degrees down; stops halfway and at the end.
    f.write("# t x y z yaw_deg pitch_deg\n")
    mid = (x0 + x1) / 2
    f.write(f"0 {x0} {y0 + 40} {cz} 90 -25\n12 {mid} {y0 + 40} {cz} 90 -25\n")
    f.write(f"17 {mid} {y0 + 40} {cz} 90 -25\n29 {x1} {y0 + 40} {cz} 90 -25\n")
    f.write(f"34 {x1} {y0 + 40} {cz} 90 -25\n")
with open(sys.argv[2] + "/jumps.path", "w") as f:
    # Four teleports 80 m up looking at a point 150 m ahead on the ground, 5 s each.
    f.write("# t x y z look tx ty tz [jump]\n")
    t = 0
    for fx, fz in ((0.25, 0.3), (0.7, 0.6), (0.4, 0.8), (0.85, 0.25)):
        x, z = x0 + fx * (x1 - x0), z0 + fz * (z1 - z0)
        line = f"{x} {y0 + 80} {z} look {x} {y0} {z - 150}"
        f.write(f"{t} {line}{' jump' if t else ''}\n{t + 5} {line}\n")
        t += 5
EOF
fly low-pass "$WORK/low-pass.path"
fly jumps "$WORK/jumps.path"
