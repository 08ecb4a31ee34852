#!/usr/bin/env bash
# What multiresolution lossless coders pay over a flat code of the same image, beside ptm's
# overhead over its own base level (docs/benchmarks.md, "Multiresolution peers"). On the codec
# study's two real images, whole, one thread each:
# - JPEG XL lossless, effort 7 (cjxl -d 0 -e 7): flat, and with its Squeeze transform (-R 1),
#   which stores the image as a lossless pyramid of resolutions in one codestream;
# - JPEG 2000 lossless (opj_compress defaults: the reversible 5/3 wavelet, 6 resolutions);
# - ptm's default pyramid and its base level coded alone (tessera-pyramid-study).
# Every peer file is decoded back and compared with the source before its figures count.
# About a minute on 2 cores once the peers are installed. Output: one Markdown table.
#   bench/multiresolution_peers.sh [BUILD_DIR]   (default: build)
set -euo pipefail
build=${1:-build}
"$(dirname "$0")/install_peers.sh" >&2
cmake --build "$build" --target tessera_pyramid_study >&2
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# The codec study's images: xplanet-images' earth.jpg (a 2048x1024 map) and
# gnome-backgrounds' wood-d.webp (a 4096x4096 photograph).
(cd "$work" && apt-get download xplanet-images gnome-backgrounds >/dev/null 2>&1)
for deb in "$work"/*.deb; do dpkg-deb -x "$deb" "$work/x"; done
declare -A inputs=(
  [map]="$work/x/usr/share/xplanet/images/earth.jpg"
  [photo]="$work/x/usr/share/backgrounds/gnome/wood-d.webp"
)

now() { date +%s.%N; }
# The pixels of a binary PPM (P6, maxval 255): its last width x height x 3 bytes.
same_pixels() { cmp -s <(tail -c "$3" "$1") <(tail -c "$3" "$2"); }

echo "| image | coder | bytes | against JPEG XL flat | decode MP/s, one thread |"
echo "|---|---|---:|---:|---:|"
for name in map photo; do
  src="${inputs[$name]}"
  vips copy "$src" "$work/$name.ppm"
  width=$(vipsheader -f width "$work/$name.ppm")
  height=$(vipsheader -f height "$work/$name.ppm")
  pixels=$((width * height))
  raw=$((pixels * 3))
  flat_bytes=0
  report() {  # coder, file, decode command (writing $work/out.ppm)
    local coder=$1 file=$2
    shift 2
    rm -f "$work/out.ppm"
    local start end
    start=$(now)
    if ! "$@" >/dev/null 2>&1; then
      echo "multiresolution_peers: $coder could not decode $name ($*)" >&2
      exit 1
    fi
    end=$(now)
    if ! same_pixels "$work/$name.ppm" "$work/out.ppm" "$raw"; then
      echo "multiresolution_peers: $coder did not decode $name losslessly" >&2
      exit 1
    fi
    local bytes
    bytes=$(stat -c %s "$file")
    ((flat_bytes == 0)) && flat_bytes=$bytes
    awk -v n="$name" -v c="$coder" -v b="$bytes" -v f="$flat_bytes" -v p="$pixels" \
      -v s="$start" -v e="$end" \
      'BEGIN { printf "| %s | %s | %d | %+.1f %% | %.1f |\n", n, c, b, 100 * (b - f) / f,
               p / (e - s) / 1e6 }'
  }
  cjxl "$work/$name.ppm" "$work/flat.jxl" -d 0 -e 7 -R 0 --num_threads=1 --quiet
  report "JPEG XL flat (-d 0 -e 7)" "$work/flat.jxl" \
    djxl "$work/flat.jxl" "$work/out.ppm" --num_threads=1
  cjxl "$work/$name.ppm" "$work/squeeze.jxl" -d 0 -e 7 -R 1 --num_threads=1 --quiet
  report "JPEG XL Squeeze pyramid (-R 1)" "$work/squeeze.jxl" \
    djxl "$work/squeeze.jxl" "$work/out.ppm" --num_threads=1
  opj_compress -i "$work/$name.ppm" -o "$work/image.j2k" >/dev/null
  report "JPEG 2000 lossless (5/3, 6 resolutions)" "$work/image.j2k" \
    opj_decompress -i "$work/image.j2k" -o "$work/out.ppm" -threads 1
  # ptm: the whole pyramid and its base level coded alone, from the codec study. Its decode
  # figure is the whole pyramid's, counted in megapixels of the image as the peers' are.
  study=$("$build/bench/tessera-pyramid-study" --seconds 0.3 --only "ptm default" "$src")
  pyramid=$(sed -n 's/^(default: \([0-9]*\) bytes.*/\1/p' <<<"$study")
  alone=$(sed -n "s/^(default's base level alone: \([0-9]*\) bytes.*/\1/p" <<<"$study")
  pyramid_mp=$(sed -n 's/.*, pyramid \([0-9.]*\) MP).*/\1/p' <<<"$study")
  mps=$(awk -F'|' '/^\| ptm default/ { gsub(/ /, "", $6); print $6 }' <<<"$study")
  awk -v n="$name" -v b="$pyramid" -v a="$alone" -v f="$flat_bytes" -v m="$mps" \
    -v p="$pixels" -v q="$pyramid_mp" 'BEGIN {
    printf "| %s | ptm default, base level alone (256-px tiles) | %d | %+.1f %% | |\n", n, a,
      100 * (a - f) / f
    printf "| %s | ptm default, whole pyramid (%+.1f %% over its base alone) | %d | %+.1f %% | %.1f |\n",
      n, 100 * (b - a) / a, b, 100 * (b - f) / f, m * p / (q * 1e6) }'
done
