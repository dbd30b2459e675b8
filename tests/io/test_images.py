"""Ordinary images in: ``tpnet_gpu.io.images.read_image`` and ``tpnet_gpu.io.stereo_io`` (load_stereo_pair, padding,
cropping; docs/rig_file.md §6, §7).

Oracles: the arrays written to tmp_path (PNG through Pillow, TIFF through tifffile) - read back exactly, in
their own units, with their bit depth; the BT.601 luma weights applied by hand in float64; NumPy's
``np.pad(mode="edge")`` for the padding; hand-made bad files, whose messages must name the argument.
"""

import struct
import zlib

import numpy as np
import pytest
import tifffile
from PIL import Image

from tpnet_gpu.io.images import ImageFormatError, read_image
from tpnet_gpu.io.stereo_io import LUMA_WEIGHTS, load_images, load_stereo_pair, pad_frames, padded_side

RNG = np.random.default_rng(7)


def _grey(dtype, shape=(21, 34)):
    return RNG.integers(0, np.iinfo(dtype).max + 1, shape, dtype=dtype)


def _write(path, array, **kw):
    if path.suffix == ".png":
        Image.fromarray(array).save(path)
    else:
        tifffile.imwrite(path, array, **kw)
    return path


CASES = [  # (suffix, dtype, channels, tifffile keywords)
    (".png", np.uint8, 0, {}), (".png", np.uint8, 3, {}), (".png", np.uint8, 4, {}), (".png", np.uint16, 0, {}),
    (".tif", np.uint8, 0, {}), (".tif", np.uint16, 0, {}), (".tif", np.uint8, 3, {"photometric": "rgb"}),
    (".tif", np.uint16, 3, {"photometric": "rgb"}), (".tif", np.uint16, 4, {"photometric": "rgb"}),
    (".tif", np.uint16, 2, {"photometric": "minisblack", "planarconfig": "contig"}),
]


@pytest.mark.parametrize("suffix, dtype, channels, kw", CASES,
                         ids=[f"{s[1:]}-{np.dtype(d).itemsize * 8}-{c}" for s, d, c, _ in CASES])
def test_read_back_exactly_in_own_units(tmp_path, suffix, dtype, channels, kw):
    array = _grey(dtype, (21, 34) + ((channels,) if channels else ()))
    image = read_image(_write(tmp_path / f"im{suffix}", array, **kw))
    bits = np.dtype(dtype).itemsize * 8
    assert (image.bits, image.white_level) == (bits, 2.0**bits - 1)
    expected = array if channels == 0 else array[..., 0] if channels == 2 else array[..., :3]
    assert image.data.dtype == np.float32 and image.data.shape == expected.shape
    np.testing.assert_array_equal(image.data, expected.astype(np.float32))
    assert image.alpha == (channels in (2, 4))


def test_tiff_variants(tmp_path):
    planar = _grey(np.uint16, (3, 20, 24))
    image = read_image(_write(tmp_path / "planar.tif", planar, photometric="rgb", planarconfig="separate"))
    np.testing.assert_array_equal(image.data, np.moveaxis(planar, 0, -1))
    white = read_image(_write(tmp_path / "white.tif", planar[0], photometric="miniswhite"))
    np.testing.assert_array_equal(white.data, 65535.0 - planar[0])  # inverted: white is high
    floats = RNG.random((16, 16), dtype=np.float32)
    image = read_image(_write(tmp_path / "f.tif", floats))
    assert image.bits is None and image.white_level == 1.0
    np.testing.assert_array_equal(image.data, floats)


def test_palette_and_bilevel_png(tmp_path):
    rgb = _grey(np.uint8, (16, 20, 3))
    Image.fromarray(rgb).convert("P").save(tmp_path / "p.png")
    palette = read_image(tmp_path / "p.png")
    np.testing.assert_array_equal(palette.data, np.asarray(Image.open(tmp_path / "p.png").convert("RGB")))
    Image.fromarray(rgb[..., 0] > 127).save(tmp_path / "b.png")
    assert set(np.unique(read_image(tmp_path / "b.png").data)) <= {0.0, 255.0}


def _png16_rgb(path, array):
    """A valid 16-bit RGB PNG written by hand (Pillow cannot write one): filter 0 on every row."""
    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    h, w, _ = array.shape
    rows = b"".join(b"\x00" + array[y].astype(">u2").tobytes() for y in range(h))
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 2, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b""))
    return path


def _bad_files(tmp_path):
    """name -> (file, part of the message)."""
    (tmp_path / "text.png").write_text("not an image")
    (tmp_path / "empty.tif").write_bytes(b"")
    good = _write(tmp_path / "good.png", _grey(np.uint8))
    (tmp_path / "truncated.png").write_bytes(good.read_bytes()[:60])
    (tmp_path / "truncated.tif").write_bytes(_write(tmp_path / "t.tif", _grey(np.uint16)).read_bytes()[:50])
    (tmp_path / "folder.png").mkdir()
    _write(tmp_path / "one.png", np.zeros((1, 1), np.uint8))
    _write(tmp_path / "thin.tif", np.zeros((40, 7), np.uint8))
    _write(tmp_path / "stack.tif", np.zeros((2, 3, 16, 16), np.uint8), photometric="minisblack")  # 4-D: 6 pages
    _write(tmp_path / "nan.tif", np.full((16, 16), np.nan, np.float32))
    _write(tmp_path / "int32.tif", np.zeros((16, 16), np.int32))
    _write(tmp_path / "mosaic.tif", np.zeros((16, 16), np.uint16), photometric="cfa",
           extratags=[(33421, "H", 2, (2, 2), True), (33422, "B", 4, (1, 0, 2, 1), True)])
    _png16_rgb(tmp_path / "rgb16.png", _grey(np.uint16, (16, 16, 3)))
    return {
        "missing.png": "image file not found",
        "text.png": "not a readable image",
        "empty.tif": "not a readable image",
        "truncated.png": "not a readable image",
        "truncated.tif": "not a readable TIFF",
        "folder.png": "expected an image file, got a folder",
        "one.png": "expected an image of at least 8x8 pixels, got 1x1",
        "thin.tif": "got 7x40",
        "stack.tif": "expected one 2-D image (H, W) or (H, W, 3|4), got 6 pages (shape (2, 3, 16, 16))",
        "nan.tif": "expected finite samples, got NaN or infinity",
        "int32.tif": "expected 8/16-bit unsigned or float samples, got int32",
        "mosaic.tif": "a raw Bayer mosaic (photometric CFA",
        "rgb16.png": "a 16-bit colour PNG",
    }


def test_bad_files_name_the_argument(tmp_path):
    for name, message in _bad_files(tmp_path).items():
        with pytest.raises((ImageFormatError, FileNotFoundError)) as err:
            read_image(tmp_path / name, name="left")
        text = str(err.value)
        assert text.startswith("left: ") and message in text and "\n" not in text, (name, text)


def test_sixteen_bit_colour_png_is_refused_not_truncated(tmp_path):
    # Oracle: Pillow itself, which reads the file written above as 8-bit RGB (the top byte of each sample).
    array = _grey(np.uint16, (16, 16, 3))
    path = _png16_rgb(tmp_path / "rgb16.png", array)
    np.testing.assert_array_equal(np.asarray(Image.open(path)), array >> 8)
    with pytest.raises(ImageFormatError, match="save it as a 16-bit TIFF"):
        read_image(path)


# --- stereo pairs -------------------------------------------------------------------------------------------
def test_pair_rgb_to_luma_and_padding(tmp_path):
    left, right = _grey(np.uint8, (21, 34, 3)), _grey(np.uint8, (21, 34, 3))
    frames = load_stereo_pair(_write(tmp_path / "l.png", left), _write(tmp_path / "r.png", right))
    assert frames.frames.shape == (2, 24, 40) and frames.frames.dtype == np.float32
    assert frames.size == (21, 34) and frames.padded == (24, 40) and frames.tiles == (3, 5)
    assert (frames.white_level, frames.bits, frames.cfa, frames.cams) == (255.0, 8, None, 2)
    weights = np.array([0.299, 0.587, 0.114])
    assert LUMA_WEIGHTS == tuple(weights)
    for i, rgb in enumerate((left, right)):
        luma = rgb.astype(np.float64) @ weights
        np.testing.assert_allclose(frames.frames[i], np.pad(luma, ((0, 3), (0, 6)), mode="edge"), rtol=1e-6)
    assert np.all(np.isfinite(frames.frames))
    np.testing.assert_array_equal(frames.crop_image(frames.frames)[0], frames.frames[0, :21, :34])
    small = _write(tmp_path / "s.png", _grey(np.uint8, (8, 12)))  # padded to the 16x16 minimum: 2x2 tiles
    frames = load_stereo_pair(small, small)
    assert (frames.padded, frames.tiles) == ((16, 16), (1, 2))
    grid = np.arange(4.0).reshape(2, 2)
    np.testing.assert_array_equal(frames.crop_tiles(grid), [[0.0, 1.0]])  # ceil(8/8) x ceil(12/8) tiles
    assert frames.crop_image(np.zeros((4, 16, 16))).shape == (4, 8, 12)


@pytest.mark.parametrize("colour, weights", [("mean", (1 / 3, 1 / 3, 1 / 3)), ("green", (0, 1, 0))])
def test_other_colour_rules(tmp_path, colour, weights):
    rgb = _grey(np.uint16, (16, 24, 3))
    path = _write(tmp_path / "c.tif", rgb, photometric="rgb")
    frames = load_stereo_pair(path, path, colour=colour)
    np.testing.assert_allclose(frames.frames[1], rgb.astype(np.float64) @ np.array(weights), rtol=1e-6)
    assert (frames.white_level, frames.bits, frames.padded) == (65535.0, 16, (16, 24))


def test_grey_and_rgb_mix_and_16_bit_units(tmp_path):
    grey, rgb = _grey(np.uint16, (16, 16)), _grey(np.uint16, (16, 16, 3))
    frames = load_stereo_pair(_write(tmp_path / "g.png", grey), _write(tmp_path / "c.tif", rgb, photometric="rgb"))
    np.testing.assert_array_equal(frames.frames[0], grey)  # 16-bit values, not rescaled
    assert frames.white_level == 65535.0


def test_pair_errors_name_both(tmp_path):
    a = _write(tmp_path / "a.png", _grey(np.uint8, (16, 20)))
    b = _write(tmp_path / "b.png", _grey(np.uint8, (16, 21)))
    c = _write(tmp_path / "c.png", _grey(np.uint16, (16, 20)))
    with pytest.raises(ValueError, match=r"left and right: expected the same size, got 20x16 \(.*a.png\) and "
                                         r"21x16 \(.*b.png\)"):
        load_stereo_pair(a, b)
    with pytest.raises(ValueError, match=r"left and right: expected the same bit depth, got white level 255 "
                                         r"\(.*a.png\) and 65535"):
        load_stereo_pair(a, c)
    with pytest.raises(FileNotFoundError, match="right: image file not found"):
        load_stereo_pair(a, tmp_path / "none.png")
    with pytest.raises(ValueError, match="colour: expected one of"):
        load_stereo_pair(a, a, colour="red")
    with pytest.raises(ValueError, match=r"camera 2: .*at least 8x8"):
        load_images([a, a, _write(tmp_path / "tiny.png", np.zeros((4, 4), np.uint8))],
                    names=["camera 0", "camera 1", "camera 2"])


def test_padding_rules():
    # Oracle: np.pad(mode="edge") for period 1; for period 2 the last 2x2 cell repeats (a Bayer mosaic keeps
    # its pattern: every padded pixel has the parity of its source).
    assert [padded_side(n) for n in (1, 8, 9, 15, 16, 17, 24, 25)] == [16, 16, 16, 16, 16, 24, 24, 32]
    frames = RNG.random((2, 10, 19), dtype=np.float32)
    np.testing.assert_array_equal(pad_frames(frames), np.pad(frames, ((0, 0), (0, 6), (0, 5)), mode="edge"))
    same = RNG.random((1, 16, 24), dtype=np.float32)
    assert pad_frames(same) is same
    mosaic = np.tile(np.array([[1.0, 2.0], [3.0, 4.0]], np.float32), (1, 5, 9))  # (1, 10, 18)
    padded = pad_frames(mosaic, period=2)
    assert padded.shape == (1, 16, 24)
    np.testing.assert_array_equal(padded, np.tile(np.array([[1.0, 2.0], [3.0, 4.0]], np.float32), (1, 8, 12)))
