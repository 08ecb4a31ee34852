#!/usr/bin/env bash
# The ptm codec study (docs/benchmarks.md, "Progressive lossless pyramids (ptm): codec study"):
# fetches real imagery from Debian packages into a temporary directory and runs
# tessera-pyramid-study on it and on the synthetic source. About a minute on 2 cores.
#   bench/pyramid_study.sh [BUILD_DIR]   (default: build)
set -euo pipefail
build=${1:-build}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# xplanet-images: earth.jpg, a 2048x1024 map of the Earth (satellite colour);
# gnome-backgrounds: wood-d.webp, a 4096x4096 photograph of wood grain.
(cd "$work" && apt-get download xplanet-images gnome-backgrounds >/dev/null 2>&1)
for deb in "$work"/*.deb; do dpkg-deb -x "$deb" "$work/x"; done
"$build/bench/tessera-pyramid-study" --seconds 0.3 synthetic:2048x2048:1:3 \
  "$work/x/usr/share/xplanet/images/earth.jpg" \
  "$work/x/usr/share/backgrounds/gnome/wood-d.webp"
