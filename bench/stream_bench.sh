#!/usr/bin/env bash
# Streaming runtime benchmarks (issue 3, item 7), in one run on this machine:
#
#   1. archives: a 1-gigapixel synthetic RGB image (32768 x 32768) with 256- and 1024-px JPEG
#      q85 tiles, built once into $TESSERA_BENCH_DIR/archives (reused when present);
#   2. physical limits: the disk's sequential read bandwidth (dd iflag=direct, 4 MiB blocks),
#      buffered cold and page-cache read bandwidth (dd), 64 KiB random reads at queue depth 1
#      (O_DIRECT), JPEG 256x256 decode tiles/s on one core (tessera_codec_bench), and a check
#      that `tessera fly --cold` really drops the archive from the page cache (fincore);
#   3. Backes et al. Table 1: time to load a whole clip region after a jump, HD/FHD/UHD, 256-
#      and 1024-px tiles, page cache warm and cold, next to the paper and to the time the bytes
#      need at the measured bandwidth plus decoding on all cores;
#   4. eviction: LRU vs viewer-shift on the same paths and budgets;
#   5. the highest pan speed with >= 99% of frames at full detail (FHD, 256-px JPEG, warm).
#
# Everything goes to a fresh run folder $TESSERA_BENCH_DIR/run-<date>/ (raw summary.json and
# frames.csv of every flight, runs.jsonl with each exact command line and the load average
# when it started, limits.json, machine.txt, report.md); `latest` points at it. The Markdown
# tables are printed at the end (bench/stream_report.py).
#
# The machine is shared: figures taken while other work runs are slower than the machine is.
# The script refuses to start when the 1-minute load average is above --max-load (1.5) unless
# --force; it records the load average before every flight and how many cores other processes
# kept busy while it ran, and the report marks a table whose flights shared the machine.
#
#   bench/stream_bench.sh                 # full run, ~15 min plus the archive builds
#   bench/stream_bench.sh --quick         # dry run: 8192 x 8192 archives, short flights
#   bench/stream_bench.sh --only limits,table1 --force
set -euo pipefail

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
WORK=${TESSERA_BENCH_DIR:-/tmp/tessera-bench}
BUILD_DIR=${TESSERA_BUILD_DIR:-$REPO/build-bench}
SIZE=32768
# Seed 2: the synthetic generator's deep sea is one flat colour, stored as uniform tiles that
# cost no read and no decode; seed 2 has the most land of seeds 1, 2 and 8 at this size (8109
# of 21845 tiles encoded), and the jump spots below lie on its land.
SEED=2
QUICK=0
FORCE=0
MAX_LOAD=1.5
WAIT_S=0
ONLY="limits,table1,eviction,speed"

usage() {
  sed -n '2,27p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
  cat <<EOF
Options:
  --quick          dry run: ${SIZE}px -> 8192px archives, short flights (figures not for the docs)
  --size N         level-0 side of the synthetic image (default $SIZE)
  --only LIST      comma-separated subset of: limits,table1,eviction,speed (default all)
  --force          run even when the load average is above --max-load (tables are marked)
  --max-load X     load-average threshold (default $MAX_LOAD)
  --wait S         wait up to S seconds for the load average to fall below --max-load
Environment: TESSERA_BENCH_DIR (work dir, default /tmp/tessera-bench),
             TESSERA_BUILD_DIR (CMake build dir, default build-bench/ in the repository)
EOF
}

while [[ $# -gt 0 ]]; do
  case "$1" in
    --quick) QUICK=1 ;;
    --size) SIZE=$2; shift ;;
    --only) ONLY=$2; shift ;;
    --force) FORCE=1 ;;
    --max-load) MAX_LOAD=$2; shift ;;
    --wait) WAIT_S=$2; shift ;;
    -h|--help) usage; exit 0 ;;
    *) echo "stream_bench.sh: unknown option '$1' (--help)" >&2; exit 2 ;;
  esac
  shift
done
[[ $QUICK == 1 && $SIZE == 32768 ]] && SIZE=8192
wants() { [[ ",$ONLY," == *",$1,"* ]]; }
load1() { cut -d' ' -f1 /proc/loadavg; }
above() { awk -v a="$1" -v b="$2" 'BEGIN { exit !(a > b) }'; }

# Flight lengths: long enough for several clip-region loads per jump and stable percentages;
# --quick only checks that everything runs.
if [[ $QUICK == 1 ]]; then
  JUMP_S=2.5; EVICT_S=3; SPEED_S=2; SPEED_BISECT=1
else
  JUMP_S=10; EVICT_S=8; SPEED_S=6; SPEED_BISECT=4
fi
JUMP_FPS=240       # 4.2 ms frames: pacing must not quantise the load times
PAN_FPS=60         # a display rate: the pan search flies what a viewer would
TABLE1_CACHE_MIB=1024

# --- load average -------------------------------------------------------------------------
# Cores kept busy by everything on the machine over a 5-second sample (/proc/stat); with the
# load average, this is what decides whether the machine is quiet enough to measure.
busy_cores() {
  local a b
  a=$(head -1 /proc/stat); sleep 5; b=$(head -1 /proc/stat)
  awk -v a="$a" -v b="$b" -v n="$(nproc)" 'BEGIN {
    split(a, x); split(b, y); t = 0
    for (i = 2; i <= 9; ++i) t += y[i] - x[i]
    idle = (y[5] - x[5]) + (y[6] - x[6])
    printf "%.2f\n", (t > 0 ? (t - idle) / t * n : 0) }'
}
MAX_BUSY=0.5
waited=0
while :; do
  LOAD_AT_START=$(load1)
  BUSY_AT_START=$(busy_cores)
  if ! above "$LOAD_AT_START" "$MAX_LOAD" && ! above "$BUSY_AT_START" "$MAX_BUSY"; then break; fi
  (( waited >= WAIT_S )) && break
  echo "   load average $LOAD_AT_START, $BUSY_AT_START cores busy: waiting ($waited of $WAIT_S s)"
  sleep 10; waited=$((waited + 15))
done
echo "== at start: load average $(cat /proc/loadavg), $BUSY_AT_START of $(nproc) cores busy" \
     "(thresholds: load $MAX_LOAD, $MAX_BUSY cores)"
if above "$LOAD_AT_START" "$MAX_LOAD" || above "$BUSY_AT_START" "$MAX_BUSY"; then
  if [[ $FORCE == 0 && $QUICK == 0 ]]; then
    echo "stream_bench.sh: refusing to measure: load average $LOAD_AT_START (max $MAX_LOAD)," \
         "$BUSY_AT_START cores busy (max $MAX_BUSY): other work is using the cores; wait" \
         "(--wait S), or pass --force and the tables will say so" >&2
    exit 3
  fi
  echo "!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!"
  echo "!! WARNING: load average $LOAD_AT_START, $BUSY_AT_START cores busy: the figures of this"
  echo "!! run are NOT those of a quiet machine (other processes compete for the $(nproc) cores)."
  echo "!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!"
fi

# --- tools --------------------------------------------------------------------------------
TESSERA=$BUILD_DIR/src/tools/tessera
CODEC_BENCH=$BUILD_DIR/bench/tessera_codec_bench
if [[ ! -x $TESSERA || ! -x $CODEC_BENCH ]]; then
  echo "== building tessera and tessera_codec_bench in $BUILD_DIR"
  [[ -f $BUILD_DIR/build.ninja ]] ||
    cmake -S "$REPO" -B "$BUILD_DIR" -G Ninja -DTESSERA_BUILD_BENCH=ON -DCMAKE_BUILD_TYPE=Release
  ninja -C "$BUILD_DIR" -j2 tessera_cli tessera_codec_bench
fi

mkdir -p "$WORK/archives"
RUN=$WORK/run-$(date -u +%Y%m%dT%H%M%SZ)
mkdir -p "$RUN"
ln -sfn "$RUN" "$WORK/latest"
# Private copies: other work may rebuild $BUILD_DIR while this runs.
mkdir -p "$RUN/bin"
cp "$TESSERA" "$CODEC_BENCH" "$RUN/bin/"
TESSERA=$RUN/bin/tessera
CODEC_BENCH=$RUN/bin/tessera_codec_bench
RUNS=$RUN/runs.jsonl
: > "$RUNS"
echo "== run folder $RUN"

{
  echo "date: $(date -u '+%Y-%m-%d %H:%M:%S UTC')"
  echo "host: $(uname -n)  kernel: $(uname -srm)"
  echo "nproc: $(nproc)"
  echo "memory: $(free -h | awk '/^Mem:/ {print $2}') total"
  echo "revision: $(git -C "$REPO" rev-parse --short HEAD 2>/dev/null || echo unknown)$(
    git -C "$REPO" diff --quiet HEAD -- src include 2>/dev/null || echo ' (+ uncommitted changes in src/ or include/)')"
  echo "work dir filesystem: $(df -h --output=source,fstype,size "$WORK" | tail -1 | tr -s ' ')"
  echo "load average at start: $(cat /proc/loadavg); cores busy (5 s sample): $BUSY_AT_START"
  echo "command: bench/stream_bench.sh $*"
  echo "options: size=$SIZE quick=$QUICK force=$FORCE only=$ONLY"
  echo
  lscpu | head -20
} > "$RUN/machine.txt"

# Runs a command and appends to runs.jsonl its exact command line, the 1-minute load average
# before it, and how many cores *other* processes kept busy while it ran (/proc/stat busy time
# minus the command's own user+system time from /usr/bin/time): the load average counts this
# script's own threads too, so the second figure is the one that says "quiet".
# Usage: logged SECTION NAME OUT_DIR -- command...
logged() {
  local section=$1 name=$2 out=$3
  shift 4
  local load stat0 stat1 times rc=0
  load=$(load1)
  times=$(mktemp)
  stat0=$(head -1 /proc/stat)
  /usr/bin/time -f '%e %U %S' -o "$times" "$@" || rc=$?
  stat1=$(head -1 /proc/stat)
  python3 - "$section" "$name" "$out" "$load" "$stat0" "$stat1" "$(tail -1 "$times")" \
    "$(getconf CLK_TCK)" "$(nproc)" "$rc" "$@" >> "$RUNS" <<'EOF'
import json, shlex, sys
section, name, out, load, stat0, stat1, times, tck, cores, rc, *cmd = sys.argv[1:]
a = [int(v) for v in stat0.split()[1:]]
b = [int(v) for v in stat1.split()[1:]]
d = [y - x for x, y in zip(a, b)]
total = sum(d[:8])                # user nice system idle iowait irq softirq steal
busy = total - d[3] - d[4]
try:
    wall_s, user_s, sys_s = (float(v) for v in times.split())
except ValueError:
    wall_s, user_s, sys_s = 0.0, 0.0, 0.0
own = (user_s + sys_s) * int(tck)
foreign = max(0.0, (busy - own) / total * int(cores)) if total > 0 else 0.0
print(json.dumps({"section": section, "name": name, "out": out, "load1": float(load),
                  "wall_s": wall_s, "own_cpu_s": user_s + sys_s,
                  "foreign_cores": round(foreign, 3), "rc": int(rc),
                  "command": shlex.join(cmd)}))
EOF
  rm -f "$times"
  return "$rc"
}

# fly SECTION NAME ARCHIVE fly-options...: one flight into $RUN/SECTION/NAME.
fly() {
  local section=$1 name=$2 archive=$3
  shift 3
  local out=$RUN/$section/$name
  mkdir -p "$out"
  logged "$section" "$name" "$out" -- "$TESSERA" fly "$archive" --out "$out" -q "$@"
}

warm() { cat "$1" > /dev/null; }
resident_bytes() { fincore --bytes --noheadings --output RES "$1" | tr -d ' '; }

# --- 1. archives --------------------------------------------------------------------------
ARCH256=$WORK/archives/synthetic-${SIZE}-s${SEED}-t256-jpeg85.tess
ARCH1024=$WORK/archives/synthetic-${SIZE}-s${SEED}-t1024-jpeg85.tess
for pair in "256:$ARCH256" "1024:$ARCH1024"; do
  tile=${pair%%:*}
  archive=${pair#*:}
  if [[ ! -f $archive ]]; then
    echo "== building $archive"
    # Not a measurement: niced, so it takes spare cycles only.
    logged build "t$tile" "$archive" -- nice -n 10 "$TESSERA" build "synthetic:${SIZE}x${SIZE}:${SEED}:3" \
      -o "$archive" --tile "$tile" --codec jpeg --quality 85 --json > "$RUN/build-t$tile.json"
  fi
done
ls -l "$ARCH256" "$ARCH1024" | tee -a "$RUN/machine.txt"

# --- 2. physical limits -------------------------------------------------------------------
LIMITS=$RUN/limits.json
DDFILE=$WORK/ddtest-1GiB.bin
# dd's summary line: "N bytes (...) copied, S s, R MB/s" -> bytes per second.
dd_bps() { awk '/copied/ { for (i = 1; i <= NF; ++i) if ($i ~ /^s,?$/) s = $(i - 1); b = $1 }
                 END { printf "%.0f\n", b / s }'; }
drop() { dd if="$1" iflag=nocache count=0 status=none; }   # POSIX_FADV_DONTNEED on the file

if wants limits; then
  echo "== physical limits"
  if [[ ! -f $DDFILE ]]; then
    # Random bytes, so no layer below (thin provisioning, compression) can shortcut the reads.
    head -c 1G /dev/urandom > "$DDFILE.tmp" && sync && mv "$DDFILE.tmp" "$DDFILE"
  fi
  disk=(); buffered=(); cache=()
  for _ in 1 2 3; do
    disk+=("$(logged limits dd-direct - -- dd if="$DDFILE" of=/dev/null bs=4M iflag=direct 2>&1 | dd_bps)")
  done
  drop "$DDFILE"
  dropped_res=$(resident_bytes "$DDFILE")
  buffered+=("$(logged limits dd-buffered-cold - -- dd if="$DDFILE" of=/dev/null bs=4M 2>&1 | dd_bps)")
  warm "$DDFILE"
  warm_res=$(resident_bytes "$DDFILE")
  for _ in 1 2 3; do
    cache+=("$(logged limits dd-page-cache - -- dd if="$DDFILE" of=/dev/null bs=1M 2>&1 | dd_bps)")
  done
  # 64 KiB reads at random aligned offsets, one at a time, bypassing the page cache.
  random_bps=$(python3 - "$DDFILE" <<'EOF'
import mmap, os, random, sys, time
fd = os.open(sys.argv[1], os.O_RDONLY | os.O_DIRECT)
size = os.fstat(fd).st_size
buf = mmap.mmap(-1, 65536)   # page-aligned, as O_DIRECT needs
rng = random.Random(1)
n = 2000
t0 = time.perf_counter()
for _ in range(n):
    os.preadv(fd, [buf], rng.randrange(size // 65536) * 65536)
print(round(n * 65536 / (time.perf_counter() - t0)))
EOF
)
  # One core, JPEG 256x256 RGB q85 4:2:0 decode (bench/codec_bench.cpp), 3 repetitions.
  logged limits codec-bench "$RUN/codec_bench.json" -- "$CODEC_BENCH" \
    --benchmark_filter='^jpeg_tile_decode/codec:[0-9]+/side:256/ch:3/' \
    --benchmark_repetitions=3 --benchmark_report_aggregates_only=true \
    --benchmark_out="$RUN/codec_bench.json" --benchmark_out_format=json > /dev/null

  # Does `fly --cold` drop the archive's pages? Warm it, fly 50 ms with --cold, and count the
  # archive's resident bytes: they fall to about what that flight read back.
  warm "$ARCH256"
  arch_size=$(stat -c %s "$ARCH256")
  before=$(resident_bytes "$ARCH256")
  fly limits cold-check "$ARCH256" --path jump --duration 0.05 --fps 240 --cold \
    --viewport 1920x1080
  after=$(resident_bytes "$ARCH256")

  python3 - "$LIMITS" "$RUN/codec_bench.json" "$RUN/limits/cold-check/summary.json" <<EOF
import json, statistics, sys
bench = json.load(open(sys.argv[2]))
median = [b for b in bench["benchmarks"] if b.get("aggregate_name") == "median"][0]
fly = json.load(open(sys.argv[3]))
limits = {
  "disk_seq_direct_bps": statistics.median([${disk[*]/%/,}]),
  "disk_seq_direct_runs_bps": [${disk[*]/%/,}],
  "buffered_cold_bps": ${buffered[0]},
  "page_cache_bps": statistics.median([${cache[*]/%/,}]),
  "page_cache_runs_bps": [${cache[*]/%/,}],
  "random_64k_qd1_direct_bps": $random_bps,
  "test_file": "$DDFILE", "test_file_bytes": $(stat -c %s "$DDFILE"),
  "test_file_resident_after_drop": $dropped_res, "test_file_resident_after_cat": $warm_res,
  "jpeg256_decode_tiles_s_one_core": median["items_per_second"],
  "codec_bench_name": median["name"],
  "cores": $(nproc),
  "cold_check": {"archive": "$ARCH256", "archive_bytes": $arch_size,
                 "resident_before": $before, "resident_after": $after,
                 "fly_bytes_read": fly["bytes_read"]},
}
json.dump(limits, open(sys.argv[1], "w"), indent=2)
EOF
  echo "   disk ${disk[*]} B/s, page cache ${cache[*]} B/s; cold check: $before -> $after resident bytes"
fi

# --- 3. Backes et al. Table 1 -------------------------------------------------------------
if wants table1; then
  echo "== Table 1: clip-region load after jumps (${JUMP_S} s flights, $JUMP_FPS fps)"
  # The built-in `--path jump` spots fall in open sea on this image (uniform tiles: nothing to
  # read or decode), so the same kind of flight comes from a keyframe file: five spots on land,
  # far enough apart that their level-0 clip regions do not overlap at FHD, each held for a
  # fifth of the flight. The first spot is the start; the four jumps after it are measured.
  python3 - "$RUN/jumps.path" "$SIZE" "$JUMP_S" <<'EOF'
import sys
out, size, duration = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
spots = [(0.62, 0.45), (0.88, 0.85), (0.72, 0.22), (0.85, 0.55), (0.66, 0.68)]
hold = duration / len(spots)
with open(out, "w") as f:
    f.write("# t_s x y texels_per_pixel [rotation jump]: five spots on land, %.2f s each\n" % hold)
    for i, (fx, fy) in enumerate(spots):
        x, y = round(fx * size), round(fy * size)
        f.write("%.4f %d %d 1%s\n" % (i * hold, x, y, " 0 jump" if i else ""))
        # Held until just before the next jump (a key at the jump's own time would show the
        # old spot on the jump's first frame).
        f.write("%.4f %d %d 1\n" % ((i + 1) * hold - 1e-3, x, y))
EOF
  for pair in "256:$ARCH256" "1024:$ARCH1024"; do
    tile=${pair%%:*}
    archive=${pair#*:}
    for viewport in 1280x720 1920x1080 3840x2160; do
      for state in warm cold; do
        cold=()
        if [[ $state == warm ]]; then warm "$archive"; else cold=(--cold); fi
        # --decode-bound: after the flight, each jump's tiles decoded again on every core
        # from memory, the decode part of the physical bound, measured on the same tiles.
        fly table1 "t$tile-$viewport-$state" "$archive" --path "$RUN/jumps.path" \
          --fps "$JUMP_FPS" --viewport "$viewport" --cache-mib "$TABLE1_CACHE_MIB" \
          --decode-bound "${cold[@]}"
      done
    done
  done
fi

# --- 4. eviction --------------------------------------------------------------------------
if wants eviction; then
  echo "== eviction: LRU vs viewer-shift"
  # Back and forth over 8192 px (a quarter of the image at 32768) through the middle at 4096
  # px/s: each reversal revisits what was just left behind, which is where policies differ.
  span=$((SIZE / 4))
  python3 - "$RUN/back-and-forth.path" "$SIZE" "$span" "$EVICT_S" <<'EOF'
import sys
out, size, span, duration = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
speed = 4096.0
x0, x1, y = size / 2 - span / 2, size / 2 + span / 2, size / 2
leg = span / speed
with open(out, "w") as f:
    f.write("# t_s x y texels_per_pixel: back and forth at %.0f px/s\n" % speed)
    t, x, forward = 0.0, x0, True
    while t < duration:
        f.write("%.4f %.1f %.1f 1\n" % (t, x, y))
        t += leg
        x = x1 if forward else x0
        forward = not forward
    f.write("%.4f %.1f %.1f 1\n" % (t, x, y))
EOF
  warm "$ARCH256"
  for path in back-and-forth spiral; do
    path_arg=$path
    [[ $path == back-and-forth ]] && path_arg=$RUN/back-and-forth.path
    # Baseline: a budget that never evicts, so bytes read above it are re-reads.
    fly eviction "$path-nolimit" "$ARCH256" --path "$path_arg" --speed 4096 \
      --duration "$EVICT_S" --fps "$PAN_FPS" --viewport 1920x1080 --cache-mib 4096
    for mib in 64 128; do
      for policy in lru viewer-shift; do
        fly eviction "$path-$mib-$policy" "$ARCH256" --path "$path_arg" --speed 4096 \
          --duration "$EVICT_S" --fps "$PAN_FPS" --viewport 1920x1080 --cache-mib "$mib" \
          --eviction "$policy"
      done
    done
  done
fi

# --- 5. highest pan speed at full detail --------------------------------------------------
# A speed passes when >= 99% of the frames after the first full-detail frame are at full
# detail (the start-up load is Table 1's measurement, not the pan's). Doubling from 1000 px/s
# until a speed fails, then bisecting geometrically between the last pass and the first fail.
steady_pct() {
  python3 - "$1/frames.csv" <<'EOF'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
first = next((i for i, r in enumerate(rows) if float(r["coverage_desired"]) >= 1.0), len(rows))
rest = rows[first:]
print("%.2f" % (100.0 * sum(float(r["coverage_desired"]) >= 1.0 for r in rest) / len(rest)
                if rest else 0.0))
EOF
}
# The built-in `--path pan` bounces along one row: after its first crossing every tile is in
# the cache, so at high speed it measures cache hits. This path sweeps the image in rows a
# whole clip region apart (16 tiles of 256 px at FHD), turning at the edges (a lawn-mower
# path) so that the view always enters tiles it has not seen, at SPEED along every leg.
raster_path() {  # raster_path SPEED OUT
  python3 - "$1" "$2" "$SIZE" "$SPEED_S" <<'EOF'
import sys
speed, out, size, duration = float(sys.argv[1]), sys.argv[2], int(sys.argv[3]), float(sys.argv[4])
half_w, half_h, row_step = 960, 540, 16 * 256
x0, x1 = half_w, size - half_w
rows = [half_h + i * row_step for i in range(max(1, (size - 2 * half_h) // row_step + 1))]
# Corners of the lawn-mower path, then keyframes at each corner until `duration`, the last
# one interpolated (a keyframe file's flight lasts until its last key).
corners, x = [], x0
for i, y in enumerate(rows):
    corners.append((x, y))
    x = x1 if x == x0 else x0
    corners.append((x, y))
keys, t = [(0.0, corners[0][0], corners[0][1])], 0.0
for (ax, ay), (bx, by) in zip(corners, corners[1:]):
    leg = (abs(bx - ax) + abs(by - ay)) / speed
    if t + leg >= duration:
        u = (duration - t) / leg
        keys.append((duration, ax + (bx - ax) * u, ay + (by - ay) * u))
        break
    t += leg
    keys.append((t, bx, by))
with open(out, "w") as f:
    f.write("# t_s x y texels_per_pixel: rows %d px apart at %.0f px/s\n" % (row_step, speed))
    for t, x, y in keys:
        f.write("%.4f %.1f %.1f 1\n" % (t, x, y))
EOF
}
pan() {  # pan SPEED -> prints the steady full-detail percentage
  warm "$ARCH256"
  mkdir -p "$RUN/speed"
  raster_path "$1" "$RUN/speed/raster-$1.path"
  fly speed "pan-$1" "$ARCH256" --path "$RUN/speed/raster-$1.path" --duration "$SPEED_S" \
    --fps "$PAN_FPS" --viewport 1920x1080
  steady_pct "$RUN/speed/pan-$1"
}
if wants speed; then
  echo "== highest pan speed with >= 99% of frames at full detail (FHD, 256 px, warm)"
  pass=0; fail=0; speed=1000
  while (( speed <= 1024000 )); do
    pct=$(pan $speed)
    echo "   $speed px/s: $pct% at full detail"
    if above 99 "$pct"; then fail=$speed; break; fi
    pass=$speed; speed=$((speed * 2))
  done
  if (( pass > 0 && fail > 0 )); then
    for _ in $(seq "$SPEED_BISECT"); do
      speed=$(awk -v a=$pass -v b=$fail 'BEGIN { printf "%d\n", sqrt(a * b) / 100 + 0.5 }')00
      (( speed <= pass || speed >= fail )) && break
      pct=$(pan "$speed")
      echo "   $speed px/s: $pct% at full detail"
      if above 99 "$pct"; then fail=$speed; else pass=$speed; fi
    done
  fi
  [[ -d $RUN/speed/pan-50000 ]] || pct=$(pan 50000)
  echo "{\"highest_pass_px_s\": $pass, \"lowest_fail_px_s\": $fail}" > "$RUN/speed/search.json"
fi

# --- 6. report ----------------------------------------------------------------------------
echo "== load average at end: $(cat /proc/loadavg)"
python3 "$REPO/bench/stream_report.py" "$RUN" | tee "$RUN/report.md"
echo "== wrote $RUN/report.md, runs.jsonl (commands), limits.json and every flight's summary.json"
