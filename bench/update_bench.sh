#!/usr/bin/env bash
# In-place update of a 4-gigapixel archive (issue 32, item 3): bytes written and time of
# `tessera update` replacing a 256 x 256 region, against the targets (< 1 MiB, < 100 ms).
#
#   1. a synthetic 65536 x 65536 RGB archive (256-px JPEG q85 tiles, no border) is built once
#      into $TESSERA_BENCH_DIR/update (reused when present; the build takes minutes);
#   2. a 256 x 256 patch (a synthetic image) is written as PNG;
#   3. `tessera update --json` replaces the region at a few positions (tile-aligned, straddling
#      four tiles, at the image's edge), each on the archive as the previous one left it; the
#      report's bytes_written and the command's wall time (process start included) are
#      printed per position, then `tessera verify` checks the result and `tessera compact`
#      shows the dead bytes dropped.
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
echo "load average: $(cut -d' ' -f1 /proc/loadavg)"
printf '%-28s %14s %10s %12s\n' position bytes_written wall_ms tiles
for at in "32768,32768" "32896,32896" "$((SIZE - 256)),$((SIZE - 256))" "1000,2000"; do
  start=$(date +%s%N)
  json=$("$TESSERA" update "$WORK/work.tess" "$WORK/patch.png" --at "$at" --json)
  end=$(date +%s%N)
  bytes=$(python3 -c 'import json,sys; print(json.load(sys.stdin)["bytes_written"])' <<<"$json")
  tiles=$(python3 -c 'import json,sys; print(json.load(sys.stdin)["tiles_rewritten"])' <<<"$json")
  printf '%-28s %14s %10.1f %12s\n' "$at" "$bytes" "$(((end - start) / 1000))e-3" "$tiles"
done
echo "load average: $(cut -d' ' -f1 /proc/loadavg)"
"$TESSERA" info "$WORK/work.tess" | head -2
"$TESSERA" verify "$WORK/work.tess" --no-decode
