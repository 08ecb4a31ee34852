#!/usr/bin/env bash
# Merge throughput of a split build (issue 32): builds the N parts of a synthetic image once,
# then times `tessera merge` and a sequential write of the same number of bytes with fsync
# (dd conv=fsync, 1 MiB blocks, from /dev/zero) to the same directory, alternating, and prints
# each round's ratio and the median: the merge's share of the disk's sequential write speed.
# It also checks that the merge equals a single build byte for byte.
#
#   bench/merge_throughput.sh                      # 16384x16384 RGB, JPEG, 8 parts, 3 rounds
#   bench/merge_throughput.sh --size 8192 --parts 4 --rounds 5 --codec zstd
#
# The merge reads the parts from the page cache (just written), as it does on a node that has
# them cached; its time includes computing the levels above the parts and the final fsync.
set -euo pipefail

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
WORK=${TESSERA_BENCH_DIR:-/tmp/tessera-merge-bench}
TESSERA=${TESSERA:-$REPO/build/src/tools/tessera}
SIZE=16384
PARTS=8
ROUNDS=3
CODEC=jpeg
while [[ $# -gt 0 ]]; do
  case $1 in
    --size) SIZE=$2; shift 2 ;;
    --parts) PARTS=$2; shift 2 ;;
    --rounds) ROUNDS=$2; shift 2 ;;
    --codec) CODEC=$2; shift 2 ;;
    *) echo "unknown option $1" >&2; exit 2 ;;
  esac
done

mkdir -p "$WORK"
rm -f "$WORK"/part-*.tess "$WORK"/merged.tess "$WORK"/single.tess "$WORK"/dd.bin
INPUT="synthetic:${SIZE}x${SIZE}:1:3"
for i in $(seq 1 "$PARTS"); do
  "$TESSERA" build "$INPUT" --codec "$CODEC" --part "$i/$PARTS" -q -o "$WORK/part-$i.tess"
done
"$TESSERA" build "$INPUT" --codec "$CODEC" -q -o "$WORK/single.tess"

now() { date +%s.%N; }
ratios=()
for round in $(seq 1 "$ROUNDS"); do
  rm -f "$WORK/merged.tess"
  start=$(now)
  "$TESSERA" merge -q "$WORK"/part-*.tess -o "$WORK/merged.tess"
  merge_s=$(echo "$(now) - $start" | bc -l)
  bytes=$(stat -c %s "$WORK/merged.tess")
  blocks=$(( (bytes + 1048575) / 1048576 ))
  rm -f "$WORK/dd.bin"
  start=$(now)
  dd if=/dev/zero of="$WORK/dd.bin" bs=1M count="$blocks" conv=fsync status=none
  dd_s=$(echo "$(now) - $start" | bc -l)
  merge_mbs=$(echo "$bytes / $merge_s / 1000000" | bc -l)
  dd_mbs=$(echo "$blocks * 1048576 / $dd_s / 1000000" | bc -l)
  ratio=$(echo "$merge_mbs / $dd_mbs" | bc -l)
  ratios+=("$ratio")
  printf 'round %d: %d bytes, merge %.3f s (%.0f MB/s), dd %.3f s (%.0f MB/s), ratio %.2f, load %s\n' \
    "$round" "$bytes" "$merge_s" "$merge_mbs" "$dd_s" "$dd_mbs" "$ratio" \
    "$(cut -d' ' -f1 /proc/loadavg)"
done
median=$(printf '%s\n' "${ratios[@]}" | sort -g | sed -n "$(( (ROUNDS + 1) / 2 ))p")
printf 'median merge / sequential write: %.2f\n' "$median"
if cmp -s "$WORK/single.tess" "$WORK/merged.tess"; then
  echo "merged archive identical to the single build"
else
  echo "merged archive DIFFERS from the single build" >&2
  exit 1
fi
rm -f "$WORK/dd.bin"
