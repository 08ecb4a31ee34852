"""Tessera for Python: read, verify, build and stream ``.tess`` texture archives.

The C++ library does the work (the ``_tessera`` extension module); this package gives it a
Python face. See docs/python.md for the whole API, the GIL and thread safety.

    >>> import tessera
    >>> archive = tessera.open("scan.tess")            # or "http://host/scan.tess"
    >>> region = archive.read_region(0, 1000, 2000, 512, 512)   # numpy (512, 512, channels)
    >>> tessera.build(array, "out.tess", codec="zstd")          # from a NumPy array
"""

from __future__ import annotations

import os
from typing import Callable, Iterator, Optional

from . import _tessera
from ._build import build
from ._tessera import (
    BuildReport,
    CancelledError,
    CorruptError,
    Error,
    ImageInfo,
    InternalError,
    InvalidArgumentError,
    IoError,
    NotFoundError,
    TileInfo,
    TooLargeError,
    UnsupportedError,
    VerifyReport,
)

__all__ = [
    "Archive", "BuildReport", "CancelledError", "CorruptError", "Error", "ImageInfo",
    "InternalError", "InvalidArgumentError", "IoError", "NotFoundError", "Streamer", "TileInfo",
    "TooLargeError", "UnsupportedError", "VerifyReport", "build", "open",
]

__version__ = "0.1.0"


class Archive:
    """An opened archive. Thread-safe: any number of Python threads may read it at once (every
    read, decode and verify releases the GIL)."""

    def __init__(self, native: _tessera.Archive):
        self._native = native

    @property
    def name(self) -> str:
        """The path or URL it was opened from."""
        return self._native.name

    @property
    def images(self) -> list[ImageInfo]:
        """One ImageInfo per image: width, height, channels, tile_size, border, level_count,
        codec, name, and levels (a dict per level: width, height, tiles_x, tiles_y)."""
        return self._native.images

    @property
    def metadata(self) -> dict:
        """The archive's metadata block, parsed (docs/format.md, "Metadata")."""
        return self._native.metadata

    @property
    def file_bytes(self) -> int:
        return self._native.file_bytes

    def read_region(self, level: int, x: int, y: int, w: int, h: int, image: int = 0,
                    rgba: bool = False):
        """Texels [x, x + w) x [y, y + h) of `level` as an array of shape (h, w, channels) and
        the image's dtype (uint8, uint16 or float32: `images[image].dtype`), bit-exact, NaN and
        infinities included (rgba=True: uint8 RGBA, 8-bit images only). Outside the level
        texels are zero. The array owns the decoded buffer (no copy)."""
        return self._native.read_region(level, x, y, w, h, image, rgba)

    def tile_info(self, level: int, x: int, y: int, image: int = 0) -> TileInfo:
        """A tile's directory entry: kind ('encoded', 'uniform', 'empty', 'procedural'), codec,
        offset and length of its payload."""
        return self._native.tile_info(level, x, y, image)

    def read_tile(self, level: int, x: int, y: int, image: int = 0):
        """A tile's decoded texels with borders: (side, side, channels) of the image's dtype,
        side = tile_size + 2 * border."""
        return self._native.read_tile(level, x, y, image)

    def tiles(self, level: Optional[int] = None, image: int = 0,
              decode: bool = False) -> Iterator:
        """Every tile of `level` (every level, coarsest first, when None), row by row: a
        TileInfo each, or (TileInfo, texels) pairs with decode=True."""
        info = self.images[image]
        levels = [level] if level is not None else range(info.level_count - 1, -1, -1)
        for lv in levels:
            size = info.levels[lv]
            for ty in range(size["tiles_y"]):
                for tx in range(size["tiles_x"]):
                    entry = self.tile_info(lv, tx, ty, image)
                    yield (entry, self.read_tile(lv, tx, ty, image)) if decode else entry

    def verify(self, decode: bool = True, check: bool = True,
               progress: Optional[Callable[[int, int], None]] = None) -> VerifyReport:
        """Checks every checksum and structural rule, decoding every payload unless
        decode=False. Returns the report; with check=True (the default) a fault raises
        CorruptError listing the faults, with the report as its `report` attribute."""
        report = self._native.verify_report(decode, progress)
        if check and not report.ok:
            shown = "; ".join(report.faults[:10])
            more = report.fault_count - min(10, len(report.faults))
            message = f"{self.name}: {report.fault_count} fault(s): {shown}"
            if more > 0:
                message += f"; and {more} more"
            error = CorruptError(message)
            error.code = "corrupt"
            error.message = message
            error.report = report
            raise error
        return report

    def __repr__(self) -> str:
        return f"<tessera.Archive {self.name!r}, {len(self.images)} image(s)>"


def open(path_or_url: "str | os.PathLike") -> Archive:  # noqa: A001 (mirrors builtins.open)
    """Opens an archive: a local path, or an http(s):// URL (ranged reads, docs/remote.md)."""
    return Archive(_tessera.open_archive(os.fspath(path_or_url)))


class Streamer:
    """The streaming runtime for a notebook, as ``tessera fly`` drives it: give it a view (a
    centre in level-0 texels and a zoom), get the tiles that became resident and the coverage.
    Loader threads read and decode in the background; update() never waits for them, wait()
    does. Calls are serialised by the GIL: share one Streamer between threads only with care
    for the order of views."""

    def __init__(self, archive: Archive, width: int = 1280, height: int = 720,
                 cache_bytes: int = 0, loader_threads: int = 0):
        self.archive = archive
        self._native = _tessera.Streamer(archive._native, width, height, cache_bytes,
                                         loader_threads)

    def update(self, centre_x: float, centre_y: float, texels_per_pixel: float = 1.0,
               image: int = 0, rotation: float = 0.0) -> dict:
        """One frame: returns desired_level, finest_full_level, coverage (fraction of the view
        covered at the desired level), fully_covered, uploaded and released ((level, x, y)
        tuples), resident (count), queue_length, in_flight, tiles_loaded_total, failures."""
        return self._native.update(centre_x, centre_y, texels_per_pixel, image, rotation)

    def resident(self) -> list[tuple[int, int, int]]:
        """The (level, x, y) of every resident tile."""
        return self._native.resident()

    def tile(self, level: int, x: int, y: int, image: int = 0):
        """A resident tile's texels (read-only, zero-copy), or None."""
        return self._native.tile(level, x, y, image)

    def wait(self) -> None:
        """Blocks (GIL released) until the loaders have nothing left to do; the next update()
        then shows everything they loaded."""
        self._native.wait()
