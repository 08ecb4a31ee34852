"""Building archives from NumPy: an array in memory, a memory-mapped array larger than you
would like to load, and a generator of row bands. python3 examples/build_from_array.py [OUT_DIR]
"""

import sys
import tempfile
from pathlib import Path

import numpy as np

import tessera

out_dir = Path(sys.argv[1] if len(sys.argv) > 1 else tempfile.mkdtemp())
out_dir.mkdir(parents=True, exist_ok=True)

# An array in memory: a colour gradient, stored losslessly (png) so it reads back exactly.
height, width = 1000, 1500
y, x = np.mgrid[0:height, 0:width]
pixels = np.stack([x * 255 // width, y * 255 // height, (x + y) % 256], axis=-1).astype(np.uint8)


def show(progress):
    print(f"\r{progress['pixels_done'] / progress['pixels_total']:.0%}", end="", flush=True)


report = tessera.build(pixels, out_dir / "array.tess", codec="png", progress=show)
print(f"\narray.tess: {report.output_bytes} bytes, {report.tiles_encoded} tiles encoded")
back = tessera.open(out_dir / "array.tess").read_region(0, 0, 0, width, height)
assert np.array_equal(back, pixels)

# A memory-mapped array: the builder slices it one band of rows at a time, so only a band is
# ever read into memory (a zarr or dask array works the same: anything with .shape and
# row slicing).
mapped = np.lib.format.open_memmap(out_dir / "big.npy", mode="w+", dtype=np.uint8,
                                   shape=(height, width, 3))
mapped[...] = pixels
mapped.flush()
tessera.build(np.load(out_dir / "big.npy", mmap_mode="r"), out_dir / "mapped.tess",
              codec="zstd")


# A generator of row bands (a scanner, a tiled reader, a computation): give the shape up front.
def bands(rows=100):
    for top in range(0, height, rows):
        yield pixels[top:top + rows]


tessera.build(bands(), out_dir / "bands.tess", codec="webp", shape=(height, width, 3))
for name in ("array", "mapped", "bands"):
    archive = tessera.open(out_dir / f"{name}.tess")
    same = np.array_equal(archive.read_region(0, 0, 0, width, height), pixels)
    print(f"{name}.tess: {archive.images[0]}, texels identical: {same}")
