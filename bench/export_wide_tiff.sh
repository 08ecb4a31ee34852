#!/usr/bin/env bash
# `tessera export --to tiff` of u16 and f32 images (issue 33, items 2, 4 and 5): a zstd archive,
# whose payloads are copied as TIFF ZSTD tiles, against a zdelta one, whose tiles are decoded and
# compressed again by libtiff (ZSTD level 1, the type's predictor), with `cp` + `sync` of the
# archive beside them as the disk's floor. Two SIZE x SIZE one-channel sources made by vips:
# u16, two sine waves plus Gaussian noise of sigma 40 (compressible), and f32 Gaussian noise
# (not). Then the import back: `tessera build --codec zstd` of each exported TIFF, whose tiles
# are copied as stored from the zstd archive's TIFF and decoded and encoded from the zdelta
# one's (its directories have a predictor). Each command alternates with the others, --runs
# times; medians of the wall time, the outputs removed and synced before each. The inputs stay
# in the page cache.
#
# Usage: bench/export_wide_tiff.sh [--size 4096] [--runs 3] [--dir out/bench-export-wide]
# Environment: TESSERA_BIN (default: build/ of this checkout). Needs vips (libvips-tools).
set -euo pipefail

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
size=4096
runs=3
dir=$repo/out/bench-export-wide
while (($#)); do
  case $1 in
    --size) size=$2; shift 2 ;;
    --runs) runs=$2; shift 2 ;;
    --dir) dir=$2; shift 2 ;;
    -h | --help) sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) echo "export_wide_tiff: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done
tessera=${TESSERA_BIN:-$repo/build/src/tools/tessera}
[[ -x $tessera ]] || { echo "export_wide_tiff: $tessera missing: build it first" >&2; exit 1; }
command -v vips >/dev/null || { echo "export_wide_tiff: vips missing (libvips-tools)" >&2; exit 1; }
mkdir -p "$dir"
if [[ ! -f $dir/u16-$size.tif ]]; then
  vips sines "$dir/s.v" "$size" "$size" --hfreq 3 --vfreq 2
  vips linear "$dir/s.v" "$dir/s2.v" 20000 30000
  vips gaussnoise "$dir/n.v" "$size" "$size" --sigma 40
  vips add "$dir/s2.v" "$dir/n.v" "$dir/s3.v"
  vips cast "$dir/s3.v" "$dir/u16.v" ushort
  vips tiffsave "$dir/u16.v" "$dir/u16-$size.tif"
  vips gaussnoise "$dir/f.v" "$size" "$size"
  vips tiffsave "$dir/f.v" "$dir/f32-$size.tif"
  rm -f "$dir"/*.v
fi
archives=()
for type in u16 f32; do
  for codec in zstd zdelta; do
    archive=$dir/$type-$codec-$size.tess
    [[ -f $archive ]] || "$tessera" build "$dir/$type-$size.tif" -o "$archive" --codec "$codec" --quiet
    cat "$archive" >/dev/null
    archives+=("$archive")
  done
done

# The TIFFs the import reads, exported once, outside the timings.
for archive in "${archives[@]}"; do
  [[ -f ${archive%.tess}.tif ]] || "$tessera" export "$archive" --to tiff "${archive%.tess}.tif" --quiet
  cat "${archive%.tess}.tif" >/dev/null
done

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
declare -A export_s copy_s import_s
for ((r = 0; r < runs; ++r)); do
  for archive in "${archives[@]}"; do
    export_s[$archive]+=" $(seconds "$tessera" export "$archive" --to tiff "$dir/out.tif" --quiet)"
    copy_s[$archive]+=" $(seconds copy_and_sync "$archive" "$dir/out.tess")"
    import_s[$archive]+=" $(seconds "$tessera" build "${archive%.tess}.tif" -o "$dir/out.tess" \
      --codec zstd --quiet)"
  done
done
median() { tr ' ' '\n' <<<"$1" | sed '/^$/d' | sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
echo "${size}x$size, one channel; load $(cut -d' ' -f1-3 /proc/loadavg); $runs runs, median"
echo
echo "| archive | archive MiB | TIFF MiB | tiles copied | export s | cp + sync s | import --codec zstd: tiles copied | import s |"
echo "|---|---:|---:|---:|---:|---:|---:|---:|"
for archive in "${archives[@]}"; do
  summary=$("$tessera" export "$archive" --to tiff "$dir/out.tif")
  copied=$(sed -n 's/.*(\([0-9]*\) copied.*/\1/p' <<<"$summary")
  tiles=$(sed -n 's/.*: \([0-9]*\) zstd tiles.*/\1/p' <<<"$summary")
  imported=$("$tessera" build "${archive%.tess}.tif" -o "$dir/out.tess" --codec zstd --json)
  back=$(sed -n 's/.*"tiles_copied": \([0-9]*\).*/\1/p' <<<"$imported")
  back_of=$(python3 -c 'import json, sys; r = json.load(sys.stdin)
print(r["tiles_copied"] + r["tiles_encoded"] + r["tiles_uniform"] + r["tiles_empty"])' <<<"$imported")
  printf '| %s | %.1f | %.1f | %s / %s | %.2f | %.2f | %s / %s | %.2f |\n' \
    "$(basename "$archive" .tess)" "$(echo "$(stat -c %s "$archive") / 1048576" | bc -l)" \
    "$(echo "$(stat -c %s "$dir/out.tif") / 1048576" | bc -l)" "$copied" "$tiles" \
    "$(median "${export_s[$archive]}")" "$(median "${copy_s[$archive]}")" "$back" "$back_of" \
    "$(median "${import_s[$archive]}")"
done
rm -rf "$dir"/out*
