#!/usr/bin/env bash
# Fetches the real pictures the procedural benchmarks cut brushes from (scikit-image's sample
# images: grass, gravel, brick, coffee, chelsea, moon) out of Debian's python3-skimage package,
# with `apt-get download` (the package is not installed and nothing is committed), then builds
# the generated instance sets of docs/procedural.md, "Figures".
#   bench/procedural_data.sh BUILD_DIR OUT_DIR [COUNTS...]   (default counts: 10000 1000000)
set -euo pipefail
build=${1:?build dir}
out=${2:?output dir}
shift 2
counts=("$@")
((${#counts[@]})) || counts=(10000 1000000)
mkdir -p "$out"
out=$(cd "$out" && pwd)
if [[ ! -f "$out/grass.png" ]]; then
  scratch=$(mktemp -d)
  trap 'rm -rf "$scratch"' EXIT
  (cd "$scratch" && apt-get download python3-skimage >/dev/null)
  dpkg-deb -x "$scratch"/python3-skimage_*.deb "$scratch/x"
  for name in grass gravel brick coffee chelsea moon; do
    cp "$scratch"/x/usr/lib/python3/dist-packages/skimage/data/$name.png "$out/"
  done
fi
for n in "${counts[@]}"; do
  [[ -f "$out/world-$n.sqlite" ]] ||
    "$build/bench/tessera-procedural-bench" setup "$out/world-$n.sqlite" --images "$out" \
      --size 65536x65536 --count "$n" --seed 29
done
