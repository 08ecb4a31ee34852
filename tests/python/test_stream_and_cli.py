"""tessera.Streamer, python -m tessera, and reading over HTTP from `tessera serve`."""

import subprocess
import sys

import numpy as np
import pytest

import tessera
from conftest import gradient


def test_streamer_covers_the_view_once_loaded(archive_path, pixels):
    archive = tessera.open(archive_path)
    streamer = tessera.Streamer(archive, width=128, height=96, loader_threads=2)
    first = streamer.update(150, 100, texels_per_pixel=1.0)
    assert first["desired_level"] == 0
    for _ in range(10):  # a frame hands over a budget of uploads; wait() loads the rest
        streamer.wait()
        frame = streamer.update(150, 100, texels_per_pixel=1.0)
        if frame["fully_covered"] and frame["coverage"] == 1.0:
            break
    assert frame["coverage"] == 1.0 and frame["fully_covered"] and frame["failures"] == []
    resident = streamer.resident()
    assert (3, 0, 0) in resident  # the coarsest level is always there
    assert (0, 2, 1) in resident  # the tile under the view's centre
    tile = streamer.tile(0, 2, 1)
    np.testing.assert_array_equal(tile, pixels[64:128, 128:192])
    assert not tile.flags.writeable
    assert streamer.tile(0, 4, 3, image=5) is None


def test_streamer_zoomed_out_wants_a_coarser_level(archive_path):
    streamer = tessera.Streamer(tessera.open(archive_path), width=64, height=64)
    assert streamer.update(150, 100, texels_per_pixel=4.0)["desired_level"] == 2
    with pytest.raises(tessera.InvalidArgumentError):
        tessera.Streamer(tessera.open(archive_path), width=0, height=10)


def run_module(*args):
    return subprocess.run([sys.executable, "-m", "tessera", *args], capture_output=True,
                          text=True, timeout=60)


def test_python_m_tessera_info_and_verify_exit_codes(tmp_path, archive_path):
    info = run_module("info", str(archive_path))
    assert info.returncode == 0 and "300 x 200 px" in info.stdout, info.stderr
    verify = run_module("verify", str(archive_path))
    assert verify.returncode == 0 and ": OK (29 tiles" in verify.stdout, verify.stderr
    missing = run_module("info", str(tmp_path / "none.tess"))
    assert missing.returncode == 1 and missing.stderr.startswith("tessera: ")
    assert run_module("info").returncode == 2
    archive = tessera.open(archive_path)
    entry = archive.tile_info(1, 0, 0)
    data = bytearray(archive_path.read_bytes())
    data[entry.offset + 5] ^= 0x40
    archive_path.write_bytes(bytes(data))
    bad = run_module("verify", str(archive_path))
    assert bad.returncode == 3 and "tile (1,0,0)" in bad.stderr


def test_open_a_url_from_tessera_serve(cli, archive_path, pixels):
    server = subprocess.Popen([cli, "serve", str(archive_path), "--port", "0", "--threads", "1"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = server.stdout.readline()
        assert "listening on" in line, server.stderr.read()
        base = line.split("listening on", 1)[1].split()[0].rstrip("/")
        url = f"{base}/{archive_path.name}"
        archive = tessera.open(url)
        assert archive.name == url and archive.images[0].width == 300
        np.testing.assert_array_equal(archive.read_region(0, 10, 20, 100, 50),
                                      pixels[20:70, 10:110])
        with pytest.raises(tessera.Error, match="404"):
            tessera.open(f"{base}/missing.tess")
    finally:
        server.terminate()
        server.wait(timeout=30)
