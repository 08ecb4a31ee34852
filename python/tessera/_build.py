"""tessera.build: archives from files, NumPy arrays (memory-mapped ones included, or anything
sliceable by rows with a `shape`, such as zarr and dask arrays) and iterators of row bands.

The builder pulls rows top to bottom as it needs them, a band of `band_rows` rows at a time,
through a filler's fill(first_row, out): an array-like is sliced by rows, so only one band of it
is in memory at once; an iterator is consumed band by band."""

from __future__ import annotations

import os
from typing import Any, Callable, Iterable, Optional, Sequence

import numpy as np

from . import _tessera


# NumPy dtypes an image may have, by the sample type the archive stores (docs/format.md).
_SAMPLE_TYPES = {np.dtype(np.uint8): "u8", np.dtype(np.uint16): "u16",
                 np.dtype(np.float32): "f32"}


def _sample_type_of(dtype: Any, name: str) -> str:
    sample_type = _SAMPLE_TYPES.get(np.dtype(dtype))
    if sample_type is None:
        raise TypeError(f"{name}: dtype {np.dtype(dtype)} is not uint8, uint16 or float32 "
                        "(the sample types Tessera stores)")
    return sample_type


def _channels_of(shape: Sequence[int], name: str) -> int:
    if len(shape) == 2:
        return 1
    if len(shape) == 3 and 1 <= shape[2] <= 4:
        return int(shape[2])
    raise ValueError(f"{name}: shape {tuple(shape)} is not (height, width) or "
                     "(height, width, channels) with 1..4 channels")


class _ArrayFiller:
    """Rows of an array-like (ndarray, np.memmap, zarr, dask: `shape` and row slicing)."""

    def __init__(self, array: Any, name: str, band_rows: int):
        self.dtype = np.dtype(getattr(array, "dtype", np.uint8))
        self.sample_type = _sample_type_of(self.dtype, name)
        self.array = array
        self.name = name
        self.height, self.width = int(array.shape[0]), int(array.shape[1])
        self.channels = _channels_of(array.shape, name)
        self.band_rows = band_rows

    def fill(self, first_row: int, out: np.ndarray) -> None:
        rows = np.asarray(self.array[first_row:first_row + out.shape[0]], dtype=self.dtype)
        out[...] = rows.reshape(out.shape)


class _BandFiller:
    """Rows of an iterator of row bands: arrays of shape (rows, width[, channels]), any number
    of rows each. The image's shape must be given up front (the pyramid's levels depend on it)."""

    def __init__(self, bands: Iterable, shape: Sequence[int], name: str, band_rows: int,
                 dtype: Any = np.uint8):
        self.dtype = np.dtype(dtype)
        self.sample_type = _sample_type_of(self.dtype, name)
        self.bands = iter(bands)
        self.name = name
        self.height, self.width = int(shape[0]), int(shape[1])
        self.channels = _channels_of(shape, name)
        self.band_rows = band_rows
        self._pending: Optional[np.ndarray] = None  # rows of the last band not yet handed on

    def _next_band(self, row: int) -> np.ndarray:
        try:
            band = np.asarray(next(self.bands))
        except StopIteration:
            raise ValueError(f"{self.name}: the bands ended at row {row} of {self.height}") from None
        if band.dtype != self.dtype:
            raise TypeError(f"{self.name}: band at row {row} has dtype {band.dtype}, not "
                            f"{self.dtype}")
        expected = (self.width,) if self.channels == 1 and band.ndim == 2 else (
            self.width, self.channels)
        if band.ndim not in (2, 3) or band.shape[1:] != expected:
            raise ValueError(f"{self.name}: band at row {row} has shape {band.shape}, rows of "
                             f"{self.width} px x {self.channels} channel(s) expected")
        return band.reshape(band.shape[0], self.width, self.channels)

    def fill(self, first_row: int, out: np.ndarray) -> None:
        done = 0
        while done < out.shape[0]:
            if self._pending is None or len(self._pending) == 0:
                self._pending = self._next_band(first_row + done)
            take = min(out.shape[0] - done, len(self._pending))
            out[done:done + take] = self._pending[:take]
            self._pending = self._pending[take:]
            done += take
        if first_row + done == self.height:
            self._check_exhausted()

    def _check_exhausted(self) -> None:
        extra = len(self._pending) if self._pending is not None else 0
        if extra == 0:
            following = next(self.bands, None)
            extra = 0 if following is None else len(np.asarray(following))
        if extra:
            raise ValueError(f"{self.name}: the bands hold more than the {self.height} rows "
                             "of the shape given")


def _is_array_like(source: Any) -> bool:
    return hasattr(source, "shape") and hasattr(source, "__getitem__")


def _filler(source: Any, index: int, shape, name: Optional[str], band_rows: int, dtype: Any):
    label = name or ("array" if index == 0 else f"array{index}")
    if _is_array_like(source):
        return _ArrayFiller(source, label, band_rows)
    if shape is None:
        raise ValueError("building from an iterator of row bands needs shape=(height, width"
                         "[, channels])")
    return _BandFiller(source, shape, name or "bands", band_rows, dtype)


_CODEC_DEFAULT = "jpeg"
# For uint16 and float32 images: lossless, and the codec made for wide samples.
_WIDE_CODEC_DEFAULT = "zdelta"


def build(source: Any, out: "str | os.PathLike", *, tile_size: int = 256, border: int = 0,
          codec: Optional[str] = None, quality: int = 85, effort: int = 0,
          chroma_subsampling: bool = True, srgb_downsample: bool = False,
          order: str = "hilbert", threads: int = 0, page_tiles_log2: int = 5,
          image_names: Optional[Sequence[str]] = None, memory_limit: int = 0,
          spool_dir: "str | os.PathLike" = "", shape: Optional[Sequence[int]] = None,
          band_rows: int = 0, name: Optional[str] = None, dtype: Any = np.uint8,
          progress: Optional[Callable[[dict], None]] = None) -> _tessera.BuildReport:
    """Builds the archive `out` from `source`, with the options of ``tessera build``
    (docs/cli.md): a path (or "synthetic:WxH[:seed[:channels]]"), a uint8, uint16 or float32
    array-like of shape (height, width) or (height, width, channels), an iterator of row bands
    (with `shape`, and `dtype` when not uint8), or a list of those, one image each. Writes atomically: on any error nothing is left at `out`.
    progress(dict(pixels_done, pixels_total, tiles_written, elapsed_s)) is called about every
    100 ms and at the end; an exception it raises (or Ctrl-C) cancels the build and is raised.
    The default codec is the CLI's (jpeg, lossy) for 8-bit sources and zdelta (lossless) when an
    array or iterator is uint16 or float32; use png, zstd, lz4, webp, raw or zdelta for exact
    texels (uint16: zdelta, zstd, lz4, raw, png; float32: zdelta, zstd, lz4, raw). NaN and
    infinities are stored as they are. Returns the BuildReport."""
    sources = list(source) if isinstance(source, (list, tuple)) else [source]
    inputs, fillers = [], []
    for index, item in enumerate(sources):
        if isinstance(item, (str, os.PathLike)):
            if fillers:
                raise ValueError("list files before arrays and iterators (images keep that order)")
            inputs.append(os.fspath(item))
        else:
            fillers.append(_filler(item, len(fillers), shape, name, band_rows, dtype))
    if codec is None:
        wide = any(filler.sample_type != "u8" for filler in fillers)
        codec = _WIDE_CODEC_DEFAULT if wide else _CODEC_DEFAULT
    options = {
        "output": os.fspath(out), "inputs": inputs, "tile_size": tile_size, "border": border,
        "codec": codec, "quality": quality, "effort": effort,
        "chroma_subsampling": chroma_subsampling, "srgb_downsample": srgb_downsample,
        "order": order, "threads": threads, "page_tiles_log2": page_tiles_log2,
        "image_names": list(image_names or []), "memory_limit": memory_limit,
        "spool_dir": os.fspath(spool_dir),
    }
    return _tessera.build(options, fillers, progress)
