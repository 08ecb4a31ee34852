#!/usr/bin/env bash
# Installs the Debian 12 packages Tessera needs to build, test and run its demo.
# Idempotent: packages already present are left alone, and apt is only asked when one is missing.
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config git clang-format clang-tidy clang libclang-rt-14-dev
  universal-ctags
  libtiff-dev libjpeg62-turbo-dev libturbojpeg0-dev libpng-dev libwebp-dev
  libzstd-dev liblz4-dev libxxhash-dev libsquish-dev
  libcli11-dev libfmt-dev nlohmann-json3-dev libboost-dev libcurl4-openssl-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  libepoxy-dev libegl-dev libglfw3-dev libegl-mesa0 libgl1-mesa-dri libimgui-dev
  xvfb nginx-light openssl
  chromium
  libsqlite3-dev
  libpq-dev
  postgresql
  postgresql-15-postgis-3
  libtinygltf-dev
  libassimp-dev
  libmeshoptimizer-dev
  libminizip-dev libssl-dev
  gdal-bin libvips-tools
  libopenslide-dev
  pybind11-dev python3-dev python3-numpy python3-pytest python3-venv
  slurm-wlm munge
)

# Node.js and npm for the web viewer's tests (tests/web): the machine's own Node.js (20 and
# npm 11 from NodeSource on the CI image) is kept; only a machine without `node` gets Debian's
# nodejs and npm (Debian's npm conflicts with NodeSource's nodejs, so never both).
if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
  packages+=(nodejs npm)
fi

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if ((${#missing[@]} == 0)); then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi

sudo_cmd=()
if ((EUID != 0)); then sudo_cmd=(sudo); fi
echo "install-deps: installing ${missing[*]}"
"${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -qq
"${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
