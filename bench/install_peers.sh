#!/usr/bin/env bash
# Installs the peer tools that bench/build_vs_peers.sh (and the other benchmarks)
# compare Tessera against, from Debian 12's own packages so anyone can reproduce the figures.
# Idempotent: packages already present are left alone, and apt is only asked when one is missing.
set -euo pipefail

packages=(
  libvips-tools  # vips tiffsave --tile --pyramid, vips dzsave
  gdal-bin       # gdal_translate -of COG
  libtiff-tools  # tiffinfo, to check the peers' tile layout and photometric
  time           # /usr/bin/time -v: wall time and peak RSS
  nginx-light    # static serving baseline (serve_bench.sh, link_bench.sh)
  wrk            # HTTP load generator (serve_bench.sh)
  libjxl-dev     # JPEG XL lossless column of the ptm codec study (pyramid_study.sh)
  libjxl-tools   # cjxl, djxl: JPEG XL flat and Squeeze pyramids (multiresolution_peers.sh)
  libopenjp2-tools  # opj_compress, opj_decompress: JPEG 2000 lossless (multiresolution_peers.sh)
  gir1.2-vips-8.0 python3-gi python3-gdal  # read_region peers from Python (read_region_peers.py)
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if ((${#missing[@]} == 0)); then
  echo "install_peers: all ${#packages[@]} packages present"
  exit 0
fi

sudo_cmd=()
if ((EUID != 0)); then sudo_cmd=(sudo); fi
echo "install_peers: installing ${missing[*]}"
"${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -qq
"${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
  "${missing[@]}"
# nginx starts a service on install in some setups; the benchmarks start their own instance.
if [[ " ${missing[*]} " == *" nginx-light "* ]] && command -v systemctl >/dev/null 2>&1; then
  "${sudo_cmd[@]}" systemctl disable --now nginx >/dev/null 2>&1 || true
fi
