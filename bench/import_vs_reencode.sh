#!/usr/bin/env bash
# Import of a pyramidal TIFF whose JPEG tiles fit the archive (copied as stored) against
# re-encoding the same image (`tessera build` from its base level only) and against copying
# the file (disk speed); then read_region of a 4096 x 4096 window through the Python package
# against libvips (gi.repository.Vips) on the vips pyramid and GDAL on a COG of the same image
# (bench/read_region_peers.py). Peers: bench/install_peers.sh, plus gir1.2-vips-8.0,
# python3-gi and python3-gdal for the Python side. Reported in docs/import.md.
#
# usage: bench/import_vs_reencode.sh BUILD_DIR [SIDE_PX]   (default 8192: a 8192 x 8192 RGB image)
set -euo pipefail
build=$(realpath "${1:?usage: bench/import_vs_reencode.sh BUILD_DIR [SIDE_PX]}")
side=${2:-8192}
tessera=$(realpath "$build/src/tools/tessera")
here=$(cd "$(dirname "$0")" && pwd)
work=$(mktemp -d "${TMPDIR:-/tmp}/tessera-import-bench.XXXXXX")
trap 'rm -rf "$work"' EXIT
cd "$work"

# The same picture three ways: a JPEG base level alone, the pyramid vips writes, and a COG.
"$tessera" build "synthetic:${side}x${side}:1:3" -o syn.tess --quiet
"$tessera" export syn.tess --to tiff syn.tif >/dev/null
vips tiffsave syn.tif base.tif --tile --tile-width 256 --tile-height 256 --compression jpeg --Q 85
vips tiffsave syn.tif vips.tif --tile --tile-width 256 --tile-height 256 --compression jpeg --Q 85 \
  --pyramid
gdal_translate -q -of COG -co COMPRESS=JPEG -co QUALITY=85 -co BLOCKSIZE=256 base.tif cog.tif
cat base.tif vips.tif cog.tif >/dev/null  # every side starts from the page cache

seconds() { /usr/bin/time -f %e "$@" 2>&1 >/dev/null | tail -1; }
# CPU seconds (user + system) of one run: on a shared machine the wall time mostly measures
# the other processes.
cpu() { /usr/bin/time -f "%U %S" "$@" 2>&1 >/dev/null | tail -1 | awk '{print $1 + $2}'; }
best() {  # best of three wall times of a command
  local b=""
  for _ in 1 2 3; do
    local t
    t=$(seconds "$@")
    if [[ -z $b ]] || awk "BEGIN{exit !($t < $b)}"; then b=$t; fi
  done
  echo "$b"
}
copied=$("$tessera" build vips.tif -o imported.tess --json | awk -F': ' '/tiles_copied/{gsub(",","",$2);print $2}')
encoded=$("$tessera" build vips.tif -o imported.tess --json | awk -F': ' '/tiles_encoded/{gsub(",","",$2);print $2}')
t_import=$(best "$tessera" build vips.tif -o imported.tess --quiet)
t_reencode=$(best "$tessera" build base.tif -o reencoded.tess --quiet)
t_copy=$(best sh -c 'cp vips.tif copy.bin && sync copy.bin')
c_import=$(cpu "$tessera" build vips.tif -o imported.tess --quiet)
c_reencode=$(cpu "$tessera" build base.tif -o reencoded.tess --quiet)
c_copy=$(cpu sh -c 'cp vips.tif copy.bin && sync copy.bin')
size=$(stat -c %s vips.tif)
echo "machine: $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg); image ${side}x${side} RGB, vips.tif $((size / 1048576)) MiB"
echo "import (vips pyramid, $copied tiles copied, $encoded encoded): ${t_import} s wall, ${c_import} s CPU"
echo "build from the base level (every tile encoded): ${t_reencode} s wall, ${c_reencode} s CPU  ($(awk "BEGIN{printf \"%.1f\", $t_reencode / $t_import}")x the import's wall time)"
echo "cp + sync of vips.tif (disk speed): ${t_copy} s wall, ${c_copy} s CPU"

/usr/bin/python3 "$here/read_region_peers.py" "$build" imported.tess vips.tif cog.tif
