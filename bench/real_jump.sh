#!/usr/bin/env bash
# Warm FHD jumps over real imagery (issue 30, item 6): Debian's xplanet-images earth.jpg (a
# 2048x1024 satellite map) replicated by libvips to 16384 x 16384 (268 MP), built into a
# Tessera archive (JPEG q85, 256-px tiles), then RUNS flights of `tessera fly` over the five
# jump spots of bench/stream_bench.sh's Table 1 (240 fps, FHD, 1 GiB cache, page cache warm).
# Per flight it prints the load average before it, the CPU time the flight used, and for the
# four jumps after the start the time to full detail and to the whole clip region
# (summary.json's full_detail_ms and clip_region_ms, docs/fly.md), sorted.
#
#   bench/real_jump.sh [RUNS] [TESSERA...]   # default 5 runs of build/src/tools/tessera
#
# Several binaries are flown in turn within each run (before/after comparisons under the same
# load). The machine is shared: the load average says how far from quiet each figure is.
# Environment: TESSERA_BENCH_DIR (work dir, default /tmp/tessera-bench/real-jump).
set -euo pipefail

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
work=${TESSERA_BENCH_DIR:-/tmp/tessera-bench/real-jump}
runs=${1:-5}
shift || true
binaries=("$@")
((${#binaries[@]})) || binaries=("$repo/build/src/tools/tessera")
for bin in "${binaries[@]}"; do
  [[ -x $bin ]] || { echo "real_jump.sh: $bin is not an executable (build tessera_cli)" >&2; exit 2; }
done
mkdir -p "$work"
cd "$work"

if [[ ! -s earth.jpg ]]; then
  rm -rf fetch && mkdir fetch
  (cd fetch && apt-get download xplanet-images >/dev/null 2>&1) ||
    { echo "real_jump.sh: apt-get download xplanet-images failed" >&2; exit 1; }
  dpkg-deb -x fetch/xplanet-images_*.deb fetch/x
  cp fetch/x/usr/share/xplanet/images/earth.jpg earth.jpg.tmp && mv earth.jpg.tmp earth.jpg
fi
archive=real-16384-t256-q85.tess
if [[ ! -s $archive ]]; then
  command -v vips >/dev/null ||
    { echo "real_jump.sh: needs vips (libvips-tools, scripts/install-deps.sh)" >&2; exit 1; }
  # Not measurements: niced, on spare cycles.
  nice -n 10 vips replicate earth.jpg "real-16384.tmp.tif[tile,tile-width=256,tile-height=256]" 8 16
  mv real-16384.tmp.tif real-16384.tif
  nice -n 10 "${binaries[0]}" build real-16384.tif -o "$archive.tmp" --tile 256 --codec jpeg \
    --quality 85 -q
  mv "$archive.tmp" "$archive"
  rm -f real-16384.tif
fi

# The five spots of stream_bench.sh's Table 1 at this size, 2 s each; the first is the start.
python3 - jumps.path 16384 10 <<'EOF'
import sys
out, size, duration = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
spots = [(0.62, 0.45), (0.88, 0.85), (0.72, 0.22), (0.85, 0.55), (0.66, 0.68)]
hold = duration / len(spots)
with open(out, "w") as f:
    for i, (fx, fy) in enumerate(spots):
        x, y = round(fx * size), round(fy * size)
        f.write("%.4f %d %d 1%s\n" % (i * hold, x, y, " 0 jump" if i else ""))
        f.write("%.4f %d %d 1\n" % ((i + 1) * hold - 1e-3, x, y))
EOF

echo "command: tessera fly $work/$archive --path jumps.path --fps 240 --viewport 1920x1080" \
  "--cache-mib 1024 -q --out DIR"
for run in $(seq "$runs"); do
  for bin in "${binaries[@]}"; do
    cat "$archive" >/dev/null  # warm
    out=run-$run-$(basename "$bin")
    rm -rf "$out"
    load=$(cut -d' ' -f1 /proc/loadavg)
    /usr/bin/time -f '%U %S' -o "$out.time" "$bin" fly "$archive" --path jumps.path --fps 240 \
      --viewport 1920x1080 --cache-mib 1024 -q --out "$out" >/dev/null
    python3 - "$out" "$bin" "$load" <<'EOF'
import json, sys
out, binary, load = sys.argv[1:]
s = json.load(open(out + "/summary.json"))
jumps = s["jumps"][1:]
user, system = (float(v) for v in open(out + ".time").read().split())
full = sorted(j["full_detail_ms"] for j in jumps if j["full_detail_ms"] is not None)
clip = sorted(j["clip_region_ms"] for j in jumps if j["clip_region_ms"] is not None)
print("%s load %s cpu %.2f s | full detail ms %s | clip region ms %s" % (
    binary, load, user + system, " ".join("%.0f" % v for v in full),
    " ".join("%.0f" % v for v in clip)))
EOF
  done
done
