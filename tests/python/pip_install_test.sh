#!/usr/bin/env bash
# `pip install .` as docs/python.md documents it: a fresh venv with the system site packages
# (Debian's numpy), the in-tree PEP 517 backend reusing the CMake build folder (nothing is
# compiled again), then the installed package imported from elsewhere, building and reading.
# Usage: pip_install_test.sh SOURCE_DIR BUILD_DIR PYTHON WORK_DIR
set -euo pipefail
source_dir=$1 build_dir=$2 python=$3 work=$4

rm -rf "$work"
mkdir -p "$work"
"$python" -m venv --system-site-packages "$work/venv"
# --no-index: the build needs nothing from an index (build-system.requires is empty).
"$work/venv/bin/pip" install --no-index --disable-pip-version-check -q \
  --config-settings=build-dir="$build_dir" "$source_dir"

cd "$work"
"$work/venv/bin/python" - <<'PY'
import os
import sys

import numpy as np

import tessera

where = os.path.realpath(tessera.__file__)
assert where.startswith(os.path.realpath(sys.prefix)), f"imported from {where}, not the venv"
pixels = np.arange(100 * 70 * 3, dtype=np.uint32).astype(np.uint8).reshape(100, 70, 3)
tessera.build(pixels, "pip.tess", codec="png", tile_size=64)
region = tessera.open("pip.tess").read_region(0, 0, 0, 70, 100)
assert (region == pixels).all()
print("installed tessera", tessera.__version__, "at", os.path.dirname(where))
PY
"$work/venv/bin/python" -m tessera verify -q pip.tess
"$work/venv/bin/pip" show -f tessera | grep -q "_tessera.cpython"
echo "pip install: ok"
