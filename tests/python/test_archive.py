"""tessera.open, images, levels, metadata, read_region, tiles, verify, errors."""

import threading

import numpy as np
import pytest

import tessera


def test_open_lists_images_levels_and_metadata(archive_path):
    archive = tessera.open(archive_path)
    assert archive.name == str(archive_path)
    (image,) = archive.images
    assert (image.width, image.height, image.channels, image.tile_size) == (300, 200, 3, 64)
    assert image.level_count == 4  # until one tile holds the level
    assert [(lv["width"], lv["height"], lv["tiles_x"], lv["tiles_y"]) for lv in image.levels] == [
        (300, 200, 5, 4), (150, 100, 3, 2), (75, 50, 2, 1), (38, 25, 1, 1)]
    assert archive.metadata["build"]["codec"] == "png"
    assert archive.metadata["images"][0]["source"] == "array"
    assert archive.file_bytes == archive_path.stat().st_size


def test_read_region_returns_the_built_pixels(archive_path, pixels):
    archive = tessera.open(archive_path)
    region = archive.read_region(0, 37, 21, 150, 90)
    assert region.dtype == np.uint8 and region.shape == (90, 150, 3)
    np.testing.assert_array_equal(region, pixels[21:111, 37:187])
    # The whole level, and texels outside it read as zero.
    np.testing.assert_array_equal(archive.read_region(0, 0, 0, 300, 200), pixels)
    outside = archive.read_region(0, 290, 190, 20, 20)
    np.testing.assert_array_equal(outside[:10, :10], pixels[190:, 290:])
    assert not outside[10:].any() and not outside[:, 10:].any()


def test_read_region_owns_its_buffer_without_a_copy(archive_path):
    region = tessera.open(archive_path).read_region(0, 0, 0, 64, 64)
    assert region.flags.owndata is False and region.base is not None  # the capsule owns it
    assert region.flags.writeable and region.flags.c_contiguous


def test_read_region_rgba_and_coarser_levels(archive_path, pixels):
    archive = tessera.open(archive_path)
    rgba = archive.read_region(0, 0, 0, 10, 10, rgba=True)
    assert rgba.shape == (10, 10, 4)
    np.testing.assert_array_equal(rgba[..., :3], pixels[:10, :10])
    assert (rgba[..., 3] == 255).all()
    coarse = archive.read_region(2, 0, 0, 75, 50)
    assert coarse.shape == (50, 75, 3)
    # Level 2 averages 4x4 blocks of level 0 (box filter, rounded): close to the mean.
    block_mean = pixels[:4, :4].reshape(-1, 3).mean(axis=0)
    assert np.abs(coarse[0, 0].astype(float) - block_mean).max() <= 1.0


def test_tiles_iterates_every_tile(archive_path, pixels):
    archive = tessera.open(archive_path)
    tiles = list(archive.tiles())
    assert len(tiles) == 5 * 4 + 3 * 2 + 2 * 1 + 1
    assert tiles[0].level == 3  # coarsest first
    assert all(t.kind in ("encoded", "uniform", "empty") for t in tiles)
    entry, texels = next(archive.tiles(level=0, decode=True))
    assert (entry.level, entry.x, entry.y) == (0, 0, 0)
    np.testing.assert_array_equal(texels, pixels[:64, :64])


def test_verify_good_archive(archive_path):
    calls = []
    report = tessera.open(archive_path).verify(progress=lambda done, total: calls.append(total))
    assert report.ok and report.fault_count == 0
    assert report.tiles_checked == 29 and report.payloads_checked > 0
    assert calls, "progress was never called"


def test_verify_corrupt_archive_raises_with_the_message(archive_path):
    archive = tessera.open(archive_path)
    entry = archive.tile_info(0, 2, 1)
    assert entry.kind == "encoded"
    data = bytearray(archive_path.read_bytes())
    data[entry.offset + entry.length // 2] ^= 0xFF
    archive_path.write_bytes(bytes(data))
    damaged = tessera.open(archive_path)
    with pytest.raises(tessera.CorruptError) as raised:
        damaged.verify()
    assert "tile (0,2,1)" in str(raised.value) and raised.value.code == "corrupt"
    assert raised.value.report.fault_count >= 1
    report = damaged.verify(check=False)
    assert not report.ok
    with pytest.raises(tessera.CorruptError, match=r"tile \(0,2,1\)"):
        damaged.read_region(0, 128, 64, 10, 10)


def test_errors_are_python_exceptions_with_the_library_message(tmp_path, archive_path):
    with pytest.raises(tessera.NotFoundError) as raised:
        tessera.open(tmp_path / "missing.tess")
    assert "missing.tess" in str(raised.value) and raised.value.code == "not-found"
    assert isinstance(raised.value, FileNotFoundError) and isinstance(raised.value, tessera.Error)
    (tmp_path / "junk.tess").write_bytes(b"not an archive" * 100)
    with pytest.raises(tessera.Error, match="junk.tess"):
        tessera.open(tmp_path / "junk.tess")
    archive = tessera.open(archive_path)
    with pytest.raises(tessera.InvalidArgumentError, match="level 9"):
        archive.read_region(9, 0, 0, 4, 4)
    with pytest.raises(ValueError, match="image 3"):
        archive.read_region(0, 0, 0, 4, 4, image=3)


def test_reads_from_several_threads(archive_path, pixels):
    archive = tessera.open(archive_path)
    failures = []

    def read(offset):
        for k in range(20):
            x = (offset * 7 + k * 13) % 250
            if not np.array_equal(archive.read_region(0, x, 10, 50, 50), pixels[10:60, x:x + 50]):
                failures.append(x)

    threads = [threading.Thread(target=read, args=(i,)) for i in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert failures == []
