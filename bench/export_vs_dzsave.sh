#!/usr/bin/env bash
# Deep Zoom export against libvips: `tessera export --to dzi` from an archive, against
# `vips dzsave` from the TIFF the archive was built from (issue 33's target: at least 3x faster,
# tiles copied rather than encoded), plus `--to pmtiles` and `--to mbtiles` beside them. One run,
# same input, alternating the tools; each command --runs times, the median wall time reported.
#
# Usage: bench/export_vs_dzsave.sh [--size 16384] [--runs 3] [--dir out/bench-export]
# Environment: TESSERA_BIN, TESSERA_MAKE_TIFF_BIN (binaries; default: build/ of this checkout).
set -euo pipefail

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
size=16384
runs=3
dir=$repo/out/bench-export
while (($#)); do
  case $1 in
    --size) size=$2; shift 2 ;;
    --runs) runs=$2; shift 2 ;;
    --dir) dir=$2; shift 2 ;;
    -h | --help) sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) echo "export_vs_dzsave: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done
tessera=${TESSERA_BIN:-$repo/build/src/tools/tessera}
make_tiff=${TESSERA_MAKE_TIFF_BIN:-$repo/build/bench/tessera-make-tiff}
for tool in "$tessera" "$make_tiff"; do
  [[ -x $tool ]] || { echo "export_vs_dzsave: $tool missing: build it first" >&2; exit 1; }
done
command -v vips >/dev/null || { echo "export_vs_dzsave: vips missing (bench/install_peers.sh)" >&2; exit 1; }
mkdir -p "$dir"
input=$dir/input-$size.tif
archive=$dir/input-$size.tess
[[ -f $input ]] || "$make_tiff" "$input" "${size}x${size}" --channels 3 --tile 256 >/dev/null
[[ -f $archive ]] || "$tessera" build "$input" -o "$archive" --codec jpeg --quality 85 --quiet

# seconds CMD...: wall time of one run, outputs removed before it; nan (and the command on
# stderr) when it fails, so a failed export never shows as a fast one.
seconds() {
  rm -rf "$dir"/out*
  sync
  local start end
  start=$(date +%s.%N)
  if ! "$@" >/dev/null 2>&1; then
    echo "export_vs_dzsave: failed: $*" >&2
    echo nan
    return
  fi
  end=$(date +%s.%N)
  echo "$end - $start" | bc -l
}
declare -A times
names=(tessera-dzi vips-dzsave tessera-pmtiles tessera-mbtiles)
for ((r = 0; r < runs; ++r)); do
  times[tessera-dzi]+=" $(seconds "$tessera" export "$archive" --to dzi "$dir/out.dzi" --quiet)"
  times[vips-dzsave]+=" $(seconds vips dzsave "$input" "$dir/out" --tile-size 256 --overlap 0 --suffix '.jpg[Q=85]')"
  times[tessera-pmtiles]+=" $(seconds "$tessera" export "$archive" --to pmtiles "$dir/out.pmtiles" --quiet)"
  times[tessera-mbtiles]+=" $(seconds "$tessera" export "$archive" --to mbtiles "$dir/out.mbtiles" --quiet)"
done
median() { tr ' ' '\n' <<<"$1" | sed '/^$/d' | sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
vips_s=$(median "${times[vips-dzsave]}")
echo "input ${size}x${size} RGB, JPEG q85 256 px; load $(cut -d' ' -f1-3 /proc/loadavg); $runs runs, median"
echo
echo "| command | wall s | vips dzsave / this |"
echo "|---|---:|---:|"
for name in "${names[@]}"; do
  s=$(median "${times[$name]}")
  printf '| %s | %.2f | %.2f |\n' "$name" "$s" "$(echo "$vips_s / $s" | bc -l)"
done
rm -rf "$dir"/out*
