"""read_region of a 4096 x 4096 window, level 0, as NumPy arrays: Tessera's Python package on
an archive, libvips (gi.repository.Vips: Debian has no python3-pyvips) on the pyramidal TIFF
vips writes, GDAL on a COG of the same image. Best of five, each after one warm-up read, in
one process. Run by bench/import_vs_reencode.sh.

usage: read_region_peers.py BUILD_DIR ARCHIVE VIPS_TIFF COG"""
import sys
import time

build, archive_path, vips_tiff, cog = sys.argv[1:5]
sys.path.insert(0, build + "/python")
import numpy as np  # noqa: E402
import tessera  # noqa: E402

SIDE = 4096


def best_of(read, runs=5):
    read()
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        array = read()
        times.append(time.perf_counter() - start)
    assert array.shape[:2] == (SIDE, SIDE), array.shape
    return min(times), array


# Every reader opens its file for each read, so no side keeps decoded tiles between reads
# (GDAL's block cache would otherwise serve the repeat from memory); the file's bytes are in
# the page cache for all three.
x = y = (tessera.open(archive_path).images[0].width - SIDE) // 2 // 256 * 256 + 128
results = {}
results["tessera read_region"] = best_of(
    lambda: tessera.open(archive_path).read_region(0, x, y, SIDE, SIDE))

try:
    import gi

    gi.require_version("Vips", "8.0")
    from gi.repository import GObject, Vips

    Vips.init(sys.argv[0])

    # What pyvips' Image.new_from_file and crop do, through GObject introspection.
    def vips_call(name, **properties):
        operation = Vips.Operation.new(name)
        for key, value in properties.items():
            GObject.Object.set_property(operation, key, value)
        operation = Vips.cache_operation_build(operation)
        out = GObject.Object.get_property(operation, "out")
        operation.unref_outputs()
        return out

    def vips_read():
        image = vips_call("tiffload", filename=vips_tiff)
        window = vips_call("extract_area", input=image, left=x, top=y, width=SIDE, height=SIDE)
        return np.frombuffer(window.write_to_memory(), np.uint8).reshape(SIDE, SIDE, 3)

    results["libvips tiffload + extract_area (gi)"] = best_of(vips_read)
except (ImportError, ValueError) as error:
    print(f"libvips skipped: {error}")

try:
    from osgeo import gdal

    gdal.UseExceptions()
    def gdal_read():
        dataset = gdal.Open(cog)
        return np.moveaxis(dataset.ReadAsArray(x, y, SIDE, SIDE), 0, -1)

    results["GDAL ReadAsArray (COG)"] = best_of(gdal_read)
except ImportError as error:
    print(f"GDAL skipped: {error}")

reference = results["tessera read_region"][1]
for name, (seconds, array) in results.items():
    delta = np.abs(array.astype(np.int16) - reference.astype(np.int16)).mean()
    print(f"{name}: {seconds * 1000:.0f} ms ({SIDE * SIDE / seconds / 1e6:.0f} MP/s), "
          f"mean |diff| vs tessera {delta:.2f}")
