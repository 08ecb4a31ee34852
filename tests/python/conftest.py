"""Fixtures for the Python package's tests: tiny archives built from known pixels, so every
test runs in milliseconds. Run by ctest (tests/python/CMakeLists.txt) with the build folder's
package on PYTHONPATH, or by hand: PYTHONPATH=build/python /usr/bin/python3 -m pytest tests/python
"""

import os
import shutil

import numpy as np
import pytest

import tessera


def gradient(height, width, channels, seed=0):
    """A deterministic image whose every texel differs from its neighbours'."""
    rng = np.random.default_rng(seed)
    return rng.integers(0, 256, size=(height, width, channels), dtype=np.uint8)


@pytest.fixture
def pixels():
    return gradient(200, 300, 3)


@pytest.fixture
def archive_path(tmp_path, pixels):
    """A 300 x 200 RGB archive in 64-px tiles, PNG (lossless): 4 levels."""
    out = tmp_path / "known.tess"
    tessera.build(pixels, out, codec="png", tile_size=64, threads=2)
    return out


@pytest.fixture
def cli():
    """The `tessera` binary ctest passes (TESSERA_CLI), or one on PATH; skips without it."""
    path = os.environ.get("TESSERA_CLI") or shutil.which("tessera")
    if not path:
        pytest.skip("no tessera binary (set TESSERA_CLI)")
    return path
