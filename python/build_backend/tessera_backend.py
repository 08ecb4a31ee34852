"""A PEP 517 build backend for the `tessera` Python package, in the source tree so that
`pip install .` needs no package index: it runs CMake to build the extension module target only
(tessera_python, Release), then writes the wheel itself (PEP 427: the package, the extension and
a .dist-info with METADATA, WHEEL and RECORD).

Config settings (`pip install . --config-settings=KEY=VALUE`) or environment variables:
  build-dir / TESSERA_BUILD_DIR   an existing CMake build folder to reuse (CI passes the one the
                                  library was built in, so nothing is compiled twice); default:
                                  <source>/build-python, configured on first use
  jobs / CMAKE_BUILD_PARALLEL_LEVEL   parallel compile jobs; default: CMake's
Only build_wheel (and the metadata hooks) are provided: no sdist, no editable installs.
"""

from __future__ import annotations

import base64
import hashlib
import importlib.machinery
import os
import re
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

_SOURCE = Path(__file__).resolve().parents[2]


def _project() -> dict:
    text = (_SOURCE / "pyproject.toml").read_text(encoding="utf-8")
    try:
        import tomllib
        return tomllib.loads(text)["project"]
    except ImportError:  # Python < 3.11: the few fields we need, by pattern
        fields = dict(re.findall(r'^(name|version|description|requires-python)\s*=\s*"([^"]*)"',
                                 text, re.M))
        return {**fields, "dependencies": ["numpy"]}


def _name_version() -> tuple[str, str]:
    project = _project()
    return project["name"], project["version"]


def _metadata() -> str:
    project = _project()
    lines = ["Metadata-Version: 2.1", f"Name: {project['name']}",
             f"Version: {project['version']}", f"Summary: {project.get('description', '')}",
             f"Requires-Python: {project.get('requires-python', '>=3.9')}"]
    lines += [f"Requires-Dist: {dep}" for dep in project.get("dependencies", [])]
    return "\n".join(lines) + "\n"


def _tag() -> str:
    python = f"cp{sys.version_info.major}{sys.version_info.minor}"
    platform = sysconfig.get_platform().replace("-", "_").replace(".", "_")
    return f"{python}-{python}-{platform}"


def _setting(config_settings, key: str, env: str):
    value = (config_settings or {}).get(key) or os.environ.get(env)
    return value or None


def _run(command: list[str]) -> None:
    print("tessera_backend:", " ".join(command), file=sys.stderr, flush=True)
    subprocess.run(command, check=True, stdout=sys.stderr)


def _build_extension(config_settings) -> Path:
    """Configures (when new) and builds tessera_python; returns the package folder it made."""
    build_dir = Path(_setting(config_settings, "build-dir", "TESSERA_BUILD_DIR")
                     or _SOURCE / "build-python")
    if not build_dir.is_absolute():
        build_dir = _SOURCE / build_dir
    if not (build_dir / "CMakeCache.txt").exists():
        _run(["cmake", "-S", str(_SOURCE), "-B", str(build_dir), "-G", "Ninja",
              "-DCMAKE_BUILD_TYPE=Release", "-DTESSERA_BUILD_TOOLS=OFF",
              "-DTESSERA_BUILD_PYTHON=ON", f"-DPython_EXECUTABLE={sys.executable}"])
    command = ["cmake", "--build", str(build_dir), "--target", "tessera_python"]
    jobs = _setting(config_settings, "jobs", "CMAKE_BUILD_PARALLEL_LEVEL")
    if jobs:
        command += ["-j", str(jobs)]
    _run(command)
    package = build_dir / "python" / "tessera"
    # The module must be for this interpreter: a build folder configured for another Python
    # would give a wheel that fails at import.
    suffixes = importlib.machinery.EXTENSION_SUFFIXES
    if not any(p.name.startswith("_tessera") and any(p.name.endswith(s) for s in suffixes)
               for p in package.iterdir()):
        raise RuntimeError(f"{build_dir}: no _tessera module for this Python ({sys.executable}, "
                           f"suffixes {suffixes}); configure it with -DPython_EXECUTABLE=")
    return package


def _record_line(arcname: str, data: bytes) -> str:
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{arcname},sha256={digest},{len(data)}"


def _dist_info_files() -> dict[str, bytes]:
    wheel = ("Wheel-Version: 1.0\nGenerator: tessera_backend\nRoot-Is-Purelib: false\n"
             f"Tag: {_tag()}\n")
    return {"METADATA": _metadata().encode(), "WHEEL": wheel.encode()}


# PEP 517 hooks.

def get_requires_for_build_wheel(config_settings=None):
    return []


def prepare_metadata_for_build_wheel(metadata_directory, config_settings=None):
    name, version = _name_version()
    dist_info = Path(metadata_directory) / f"{name}-{version}.dist-info"
    dist_info.mkdir(parents=True, exist_ok=True)
    for file_name, data in _dist_info_files().items():
        (dist_info / file_name).write_bytes(data)
    return dist_info.name


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    package = _build_extension(config_settings)
    name, version = _name_version()
    wheel_name = f"{name}-{version}-{_tag()}.whl"
    dist_info = f"{name}-{version}.dist-info"
    files = {}
    suffixes = tuple(importlib.machinery.EXTENSION_SUFFIXES)
    for path in sorted(package.iterdir()):
        if path.suffix == ".py" or (path.name.startswith("_tessera") and
                                    path.name.endswith(suffixes)):
            files[f"tessera/{path.name}"] = path.read_bytes()
    for file_name, data in _dist_info_files().items():
        files[f"{dist_info}/{file_name}"] = data
    record = [_record_line(arcname, data) for arcname, data in files.items()]
    record.append(f"{dist_info}/RECORD,,")
    files[f"{dist_info}/RECORD"] = ("\n".join(record) + "\n").encode()
    out = Path(wheel_directory) / wheel_name
    with zipfile.ZipFile(out, "w", compression=zipfile.ZIP_DEFLATED) as wheel:
        for arcname, data in files.items():
            info = zipfile.ZipInfo(arcname, date_time=(2020, 1, 1, 0, 0, 0))
            info.external_attr = (0o755 if arcname.endswith(suffixes) else 0o644) << 16
            info.compress_type = zipfile.ZIP_DEFLATED
            wheel.writestr(info, data)
    return wheel_name
