"""The scripts in examples/ run to the end (each checks what it shows)."""

import subprocess
import sys
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def test_build_from_array_example(tmp_path):
    run = subprocess.run([sys.executable, str(EXAMPLES / "build_from_array.py"), str(tmp_path)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.count("texels identical: True") == 3


def test_read_region_example(archive_path):
    run = subprocess.run([sys.executable, str(EXAMPLES / "read_region.py"), str(archive_path)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert "region (200, 300, 3) uint8" in run.stdout and "coverage 100%" in run.stdout
