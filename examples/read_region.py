"""Notebook-style tour of reading an archive with the `tessera` Python package.

Run it as a script (python3 examples/read_region.py [ARCHIVE_OR_URL]) or cell by cell (the
"# %%" markers) in Jupyter or VS Code. Without an argument it builds a small demo archive from
the synthetic source first. docs/python.md has the whole API.
"""

# %% Open an archive: a path or an http(s):// URL served by `tessera serve`.
import sys
import tempfile
from pathlib import Path

import tessera

if len(sys.argv) > 1:
    source = sys.argv[1]
else:
    source = str(Path(tempfile.mkdtemp()) / "demo.tess")
    tessera.build("synthetic:2048x1536:7:3", source, codec="jpeg", tile_size=256)
archive = tessera.open(source)
print(archive)
for index, image in enumerate(archive.images):
    print(index, image, [(lv["width"], lv["height"]) for lv in image.levels])

# %% Read a region of level 0 as a NumPy array (height, width, channels), no copy made.
image = archive.images[0]
w, h = min(512, image.width), min(384, image.height)
region = archive.read_region(0, (image.width - w) // 2, (image.height - h) // 2, w, h)
print("region", region.shape, region.dtype, "mean per channel", region.mean(axis=(0, 1)))

# %% The whole image at the coarsest level: a thumbnail.
coarsest = image.level_count - 1
size = image.levels[coarsest]
thumbnail = archive.read_region(coarsest, 0, 0, size["width"], size["height"])
print("thumbnail", thumbnail.shape)

# %% Iterate over the tiles of one level and count their kinds.
kinds = {}
for tile in archive.tiles(level=min(1, coarsest)):
    kinds[tile.kind] = kinds.get(tile.kind, 0) + 1
print("tiles by kind at level", min(1, coarsest), kinds)

# %% Stream a view as `tessera fly` would: which tiles are resident, and the coverage.
streamer = tessera.Streamer(archive, width=640, height=360)
frame = streamer.update(image.width / 2, image.height / 2, texels_per_pixel=2.0)
streamer.wait()
frame = streamer.update(image.width / 2, image.height / 2, texels_per_pixel=2.0)
print(f"level {frame['desired_level']}: coverage {frame['coverage']:.0%}, "
      f"{frame['resident']} tiles resident")

# %% Check every checksum (raises tessera.CorruptError naming the tile on a fault).
report = archive.verify()
print("verify:", report.tiles_checked, "tiles,", report.payloads_checked, "payloads, ok")

# %% Show the region (needs matplotlib; skipped without it).
try:
    import matplotlib.pyplot as plt
except ImportError:
    plt = None
if plt is not None and "ipykernel" in sys.modules:
    plt.imshow(region.squeeze())
    plt.show()
