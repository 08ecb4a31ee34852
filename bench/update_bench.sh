#!/usr/bin/env bash
# In-place update of a 4-gigapixel archive (issue 32, item 3): bytes written and time of
# `tessera update` replacing a 256 x 256 region, against the targets (< 1 MiB, < 100 ms).
#
#   1. a synthetic 65536 x 65536 RGB archive (256-px JPEG q85 tiles, no border) is built once
#      into $TESSERA_BENCH_DIR/update (reused when present; the build takes minutes);
#   2. a 256 x 256 patch (a synthetic image) is written as PNG;
#   3. `tessera update --json` replaces the region at a few positions (tile-aligned, straddling
#      four tiles, at the image's edge), each on the archive as the previous one left it; per
#      position: the report's bytes_written and elapsed time (the update itself: open, decode,
#      encode, append, two fdatasyncs), the process's CPU time (user + sys) and the command's
#      wall time (process start included); then `tessera verify --no-decode` checks the result.
#
# The machine is shared: the 1-minute load average is printed with the figures.
#
#   bench/update_bench.sh [--build-dir build] [--size 65536]
set -euo pipefail

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
WORK=${TESSERA_BENCH_DIR:-/tmp/tessera-bench}/update
BUILD_DIR=$REPO/build
SIZE=65536
while (($#)); do
  case $1 in
    --build-dir) BUILD_DIR=$2; shift 2 ;;
    --size) SIZE=$2; shift 2 ;;
    *) echo "usage: $0 [--build-dir DIR] [--size PX]" >&2; exit 2 ;;
  esac
done
TESSERA=$BUILD_DIR/src/tools/tessera
mkdir -p "$WORK"
ARCHIVE=$WORK/base-$SIZE.tess
if [[ ! -f $ARCHIVE ]]; then
  echo "building $ARCHIVE (synthetic ${SIZE}x${SIZE}, jpeg q85)..."
  /usr/bin/time -f "build: %e s, %M KiB peak RSS" \
    "$TESSERA" build "synthetic:${SIZE}x${SIZE}:2:3" -o "$ARCHIVE" --quiet
fi
"$TESSERA" build "synthetic:256x256:7:3" -o "$WORK/patch.tess" --codec png --quiet
"$TESSERA" extract "$WORK/patch.tess" --rect 0,0,256,256 -o "$WORK/patch.png" >/dev/null
cp "$ARCHIVE" "$WORK/work.tess"
# The copy's dirty pages would otherwise be written by the first update's fdatasync.
sync "$WORK/work.tess"
echo "load average: $(cut -d' ' -f1 /proc/loadavg)"
printf '%-16s %14s %12s %12s %12s %6s\n' position bytes_written update_ms cpu_ms command_ms tiles
for at in "32768,32768" "32896,32896" "$((SIZE - 256)),$((SIZE - 256))" "1000,2000" "40000,40000"; do
  start=$(date +%s%N)
  json=$(/usr/bin/time -o "$WORK/time.txt" -f "%U %S" \
    "$TESSERA" update "$WORK/work.tess" "$WORK/patch.png" --at "$at" --json)
  end=$(date +%s%N)
  read -r user sys <"$WORK/time.txt"
  python3 - "$at" "$user" "$sys" "$(((end - start) / 1000000))" "$json" <<'PY'
import json, sys
at, user, sys_s, wall_ms, report = sys.argv[1:]
r = json.loads(report)
print(f"{at:<16} {r['bytes_written']:>14} {r['elapsed_s'] * 1e3:>12.1f} "
      f"{(float(user) + float(sys_s)) * 1e3:>12.0f} {wall_ms:>12} {r['tiles_rewritten']:>6}")
PY
done
echo "load average: $(cut -d' ' -f1 /proc/loadavg)"
"$TESSERA" info "$WORK/work.tess" | head -2
"$TESSERA" verify "$WORK/work.tess" --no-decode
