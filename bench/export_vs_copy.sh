#!/usr/bin/env bash
# PMTiles export against copying the archive (issue 33, "PMTiles export at disk speed"): one
# archive, then alternately `cp ARCHIVE COPY && sync COPY` and `tessera export --to pmtiles`
# (which syncs its output too), each --runs times; medians and their ratio. Beside them: the
# export's own time as its summary line states it (archive open to output synced, the process
# start left out; 10 ms resolution), `tessera --version` (the process start alone: loading the
# binary and its shared libraries) and `--to mbtiles`. The archive is
# synthetic:16384x16384:1:3 (RGB, 256-px JPEG q85, no border, 24.7 MB): its flat areas are
# stored as uniform tiles, whose pictures every export must encode, and its other tiles are
# copied as they are. The input stays in the page cache.
#
# Usage: bench/export_vs_copy.sh [--size 16384] [--runs 5] [--dir out/bench-export-copy]
# Environment: TESSERA_BIN (default: build/ of this checkout).
set -euo pipefail

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
size=16384
runs=5
dir=$repo/out/bench-export-copy
while (($#)); do
  case $1 in
    --size) size=$2; shift 2 ;;
    --runs) runs=$2; shift 2 ;;
    --dir) dir=$2; shift 2 ;;
    -h | --help) sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) echo "export_vs_copy: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done
tessera=${TESSERA_BIN:-$repo/build/src/tools/tessera}
[[ -x $tessera ]] || { echo "export_vs_copy: $tessera missing: build it first" >&2; exit 1; }
mkdir -p "$dir"
archive=$dir/synthetic-$size.tess
[[ -f $archive ]] || "$tessera" build "synthetic:${size}x${size}:1:3" -o "$archive" --quiet
cat "$archive" >/dev/null  # in the page cache for every command alike

# seconds CMD...: wall time of one run, outputs removed and the disk quiet before it.
seconds() {
  rm -rf "$dir"/out*
  sync
  local start end
  start=$(date +%s.%N)
  "$@" >/dev/null 2>&1
  end=$(date +%s.%N)
  echo "$end - $start" | bc -l
}
copy_and_sync() { cp "$1" "$2" && sync "$2"; }
declare -A times
names=(cp+sync tessera-pmtiles tessera-pmtiles-in-process tessera-start tessera-mbtiles)
# in_process ARGS...: the seconds the export's summary line ("... in 0.04 s") states.
in_process() {
  rm -rf "$dir"/out*
  sync
  "$tessera" "$@" | sed -n 's/.* in \([0-9.]*\) s$/\1/p'
}
for ((r = 0; r < runs; ++r)); do
  times[cp+sync]+=" $(seconds copy_and_sync "$archive" "$dir/out.tess")"
  times[tessera-pmtiles]+=" $(seconds "$tessera" export "$archive" --to pmtiles "$dir/out.pmtiles" --quiet)"
  times[tessera-mbtiles]+=" $(seconds "$tessera" export "$archive" --to mbtiles "$dir/out.mbtiles" --quiet)"
  times[tessera-pmtiles-in-process]+=" $(in_process export "$archive" --to pmtiles "$dir/out.pmtiles")"
  times[tessera-start]+=" $(seconds "$tessera" --version)"
done
median() { tr ' ' '\n' <<<"$1" | sed '/^$/d' | sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
copy_s=$(median "${times[cp+sync]}")
echo "archive $(basename "$archive"), $(stat -c %s "$archive") bytes; load $(cut -d' ' -f1-3 /proc/loadavg); $runs runs, median"
echo
echo "| command | wall s | this / cp+sync |"
echo "|---|---:|---:|"
for name in "${names[@]}"; do
  s=$(median "${times[$name]}")
  printf '| %s | %.3f | %.2f |\n' "$name" "$s" "$(echo "$s / $copy_s" | bc -l)"
done
rm -rf "$dir"/out*
