#!/usr/bin/env bash
# The ptm codec study (docs/benchmarks.md, "Progressive lossless pyramids (ptm): codec study"):
# fetches real imagery from Debian packages into a temporary directory and runs
# tessera-pyramid-study on it and on the synthetic source. JPEG XL lossless is a peer: the
# script installs libjxl-dev (bench/install_peers.sh) and rebuilds the study against it.
# About four minutes on 2 cores once the peers are installed, most of it libjxl's
# effort-7 and libwebp's effort-6 encoders. Standard output carries only the study's tables.
#   bench/pyramid_study.sh [BUILD_DIR]   (default: build)
set -euo pipefail
build=${1:-build}
"$(dirname "$0")/install_peers.sh" >&2
# Reconfiguring finds libjxl now that it is installed; the study is rebuilt only if that changed.
cmake "$build" >/dev/null
cmake --build "$build" --target tessera_pyramid_study >&2
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# xplanet-images: earth.jpg, a 2048x1024 map of the Earth (satellite colour);
# gnome-backgrounds: wood-d.webp, a 4096x4096 photograph of wood grain.
(cd "$work" && apt-get download xplanet-images gnome-backgrounds >/dev/null 2>&1)
for deb in "$work"/*.deb; do dpkg-deb -x "$deb" "$work/x"; done
"$build/bench/tessera-pyramid-study" --seconds 0.3 synthetic:2048x2048:1:3 \
  "$work/x/usr/share/xplanet/images/earth.jpg" \
  "$work/x/usr/share/backgrounds/gnome/wood-d.webp"
