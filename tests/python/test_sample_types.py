"""uint16 and float32 images from Python: bit-exact round trips for 1..4 channels (NaN and
infinities included), the dtype of what is read back, and the codecs that are refused."""

import numpy as np
import pytest

import tessera


def wide(height, width, channels, dtype, seed):
    rng = np.random.default_rng(seed)
    if dtype == np.uint16:
        values = rng.integers(0, 65536, size=(height, width, channels), dtype=np.uint16)
    else:
        values = (rng.standard_normal((height, width, channels)) * 1e3).astype(np.float32)
        flat = values.reshape(-1)
        flat[:4] = [np.nan, np.inf, -np.inf, -0.0]
        flat[4:5].view(np.uint32)[0] = 0x7FC0BEEF  # a NaN with a payload
    return values


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
@pytest.mark.parametrize("channels", [1, 2, 3, 4])
def test_arrays_round_trip_bit_exact(tmp_path, dtype, channels):
    if dtype == np.uint8:
        pixels = np.random.default_rng(channels).integers(0, 256, (37, 53, channels), np.uint8)
        codec = "zstd"
    else:
        pixels = wide(37, 53, channels, dtype, seed=channels)
        codec = None  # the default for wide arrays: zdelta, lossless
    out = tmp_path / "a.tess"
    tessera.build(pixels, out, codec=codec, tile_size=64, border=1)
    archive = tessera.open(out)
    info = archive.images[0]
    assert info.dtype == np.dtype(dtype)
    assert info.sample_type == {np.uint8: "u8", np.uint16: "u16", np.float32: "f32"}[dtype]
    region = archive.read_region(0, 0, 0, 53, 37)
    assert region.dtype == np.dtype(dtype) and region.shape == pixels.shape
    # Compare bit patterns: NaN != NaN, but its bits must survive.
    assert region.tobytes() == pixels.tobytes()
    assert archive.read_tile(0, 0, 0).dtype == np.dtype(dtype)
    assert archive.verify().ok


def test_uint16_bands_with_png_and_a_float_average(tmp_path):
    pixels = wide(40, 30, 1, np.uint16, seed=9)
    bands = (pixels[y:y + 16] for y in range(0, 40, 16))
    tessera.build(bands, tmp_path / "b.tess", shape=pixels.shape, dtype=np.uint16, codec="png",
                  tile_size=64)
    region = tessera.open(tmp_path / "b.tess").read_region(0, 0, 0, 30, 40)
    assert region.tobytes() == pixels.tobytes()
    # Level 1 of a float image is the mean of each 2x2 block, NaN left out.
    block = np.array([[[1.0], [np.nan]], [[2.0], [6.0]]], np.float32)
    tessera.build(np.tile(block, (64, 64, 1)), tmp_path / "f.tess", tile_size=64)
    level1 = tessera.open(tmp_path / "f.tess").read_region(1, 0, 0, 4, 4)
    assert np.all(level1 == 3.0)


def test_wide_samples_refuse_codecs_that_cannot_hold_them(tmp_path):
    with pytest.raises(tessera.InvalidArgumentError, match="u16 samples cannot be stored with "
                                                           "--codec jpeg"):
        tessera.build(np.zeros((8, 8), np.uint16), tmp_path / "o.tess", codec="jpeg")
    with pytest.raises(tessera.InvalidArgumentError, match="f32 samples cannot be stored with "
                                                           "--codec png"):
        tessera.build(np.zeros((8, 8), np.float32), tmp_path / "o.tess", codec="png")
    with pytest.raises(TypeError, match="int16"):
        tessera.build(np.zeros((8, 8), np.int16), tmp_path / "o.tess")
    with pytest.raises(tessera.UnsupportedError, match="f32 samples"):
        tessera.build(np.zeros((8, 8), np.float32), tmp_path / "z.tess")
        tessera.open(tmp_path / "z.tess").read_region(0, 0, 0, 8, 8, rgba=True)
    assert [p.name for p in tmp_path.iterdir()] == ["z.tess"]
