"""rawio: DNG/TIFF/scene round trips and bad-file errors.

Oracles: the arrays written (bit-exact, read back through rawpy/LibRaw), per-site black levels set by hand in
BlackLevel with BlackLevelRepeatDim (2, 2), and ``np.tile`` of the 2x2 black cell for ``normalised()``.
Non-Bayer and odd-layout DNGs are written directly with tifffile.
"""

import json

import numpy as np
import pytest
import tifffile

from tpnet_gpu.io import rawio
from tpnet_gpu.io.rawio import RawFormatError, RawFrame

CFAS = ("GRBG", "RGGB", "BGGR", "GBRG")
H, W = 32, 48


def mosaic(bits=12, shape=(H, W), seed=0):
    return np.random.default_rng(seed).integers(0, 1 << bits, shape, dtype=np.uint16)


def write_tiff_dng(path, data, photometric="cfa", tags=()):
    """A DNG with only the given CFA tags (for layouts write_dng refuses to make)."""
    base = [(50706, "B", 4, (1, 4, 0, 0), True), (271, "s", 0, "Acme", True), (272, "s", 0, "Q", True)]
    tifffile.imwrite(path, data, photometric=photometric, compression=None, subfiletype=0,
                     extratags=base + list(tags), metadata=None)


# --- round trips ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("bits", [12, 14, 16])
@pytest.mark.parametrize("cfa", CFAS)
def test_dng_round_trip_bit_exact(tmp_path, cfa, bits):
    data = mosaic(bits)
    path = rawio.write_dng(tmp_path / "a.dng", data, cfa, black_level=64, bits=bits)
    frame = rawio.read_raw(path)
    assert frame.data.dtype == np.uint16
    np.testing.assert_array_equal(frame.data, data)  # oracle: the array written
    assert frame.cfa == cfa
    np.testing.assert_array_equal(frame.black_level, np.full((2, 2), 64.0))
    assert frame.white_level == (1 << bits) - 1
    assert frame.source == str(path)


def test_dng_explicit_white_level(tmp_path):
    frame = rawio.read_raw(rawio.write_dng(tmp_path / "a.dng", mosaic(12), "RGGB", white_level=4000, bits=12))
    assert frame.white_level == 4000
    np.testing.assert_array_equal(frame.black_level, np.zeros((2, 2)))


@pytest.mark.parametrize("cfa", CFAS)
def test_per_site_black_level_comes_back_in_image_layout(tmp_path, cfa):
    black = np.array([[100, 101], [102, 103]])  # oracle: set by hand, row-major sites
    frame = rawio.read_raw(rawio.write_dng(tmp_path / "a.dng", mosaic(), cfa, black_level=black, bits=12))
    np.testing.assert_array_equal(frame.black_level, black)


def test_normalised_subtracts_per_site_black_unclipped():
    data = mosaic(12)
    data[0, 0] = 0  # below black: must go negative, not clip
    black = np.array([[100.0, 101.0], [102.0, 103.0]])
    out = RawFrame(data, "GRBG", black, 4095.0).normalised()
    assert out.dtype == np.float32 and out.shape == (H, W)
    expected = data.astype(np.float64) - np.tile(black, (H // 2, W // 2))  # oracle: tiled 2x2 black cell
    np.testing.assert_array_equal(out, expected.astype(np.float32))
    assert out[0, 0] == -100.0


def test_visible_area_is_cropped_and_cfa_follows_it(tmp_path):
    # ActiveArea (top, left, bottom, right) = (2, 2, 30, 46): LibRaw's raw_image_visible is data[2:30, 2:46]
    # and the CFA pattern is relative to that origin.
    data = np.arange(H * W, dtype=np.uint16).reshape(H, W)
    tags = [(33421, "H", 2, (2, 2), True), (33422, "B", 4, (0, 1, 1, 2), True), (50829, "I", 4, (2, 2, 30, 46), True)]
    write_tiff_dng(tmp_path / "a.dng", data, tags=tags)
    frame = rawio.read_raw(tmp_path / "a.dng")
    np.testing.assert_array_equal(frame.data, data[2:30, 2:46])
    assert frame.cfa == "RGGB"


@pytest.mark.parametrize("dtype", [np.uint16, np.uint8, np.float32])
def test_tiff_raw_read(tmp_path, dtype):
    data = mosaic(8).astype(dtype)
    tifffile.imwrite(tmp_path / "a.tif", data)
    frame = rawio.read_tiff_raw(tmp_path / "a.tif", "BGGR", black_level=[[1, 2], [3, 4]], white_level=250)
    np.testing.assert_array_equal(frame.data, data)  # oracle: the array written (values unchanged)
    assert frame.data.dtype == (np.float32 if dtype == np.float32 else np.uint16)
    assert (frame.cfa, frame.white_level) == ("BGGR", 250.0)
    np.testing.assert_array_equal(frame.black_level, [[1, 2], [3, 4]])
    default_white = {np.uint16: 65535.0, np.uint8: 255.0, np.float32: 1.0}[dtype]
    assert rawio.read_tiff_raw(tmp_path / "a.tif", "BGGR").white_level == default_white


def test_read_frames_mixes_dng_and_tiff_and_stacks(tmp_path):
    raws = [mosaic(12, seed=i) for i in range(4)]
    paths = [rawio.write_dng(tmp_path / f"c{i}.dng", raws[i], "GBRG", black_level=10, bits=12) for i in range(3)]
    tifffile.imwrite(tmp_path / "c3.tiff", raws[3])
    frames = rawio.read_frames([*paths, tmp_path / "c3.tiff"], cfa="GBRG", black_level=10)
    stack = rawio.stack_normalised(frames)
    assert stack.shape == (4, H, W) and stack.dtype == np.float32
    np.testing.assert_array_equal(stack, np.stack(raws).astype(np.float32) - 10)


def test_scene_round_trip(tmp_path):
    raws = np.stack([mosaic(14, seed=i) for i in range(4)])
    gt = {"disparity": np.random.default_rng(1).normal(size=(H // 8, W // 8)), "mask": np.ones((4, 6), bool),
          "centres": np.arange(24, dtype=np.float32).reshape(2, 3, 4)}
    camera = {"baseline_mm": 256.0, "focal_px": 2000.5, "offsets": [[-0.5, -0.5], [0.5, -0.5]], "name": "quad"}
    rawio.write_scene(tmp_path / "s", raws, "GRBG", black_level=[[60, 61], [62, 63]], white_level=16000,
                      ground_truth=gt, camera=camera, bits=14)
    scene = rawio.read_scene(tmp_path / "s")
    assert len(scene.frames) == 4
    for frame, raw in zip(scene.frames, raws):
        np.testing.assert_array_equal(frame.data, raw)  # oracle: the arrays written
        assert (frame.cfa, frame.white_level) == ("GRBG", 16000.0)
        np.testing.assert_array_equal(frame.black_level, [[60, 61], [62, 63]])
    assert scene.ground_truth.keys() == gt.keys()
    for name, arr in gt.items():
        np.testing.assert_array_equal(scene.ground_truth[name], arr)
        assert scene.ground_truth[name].dtype == arr.dtype
    assert scene.camera == camera
    files = sorted(p.name for p in (tmp_path / "s").iterdir())
    assert files == ["cam0.dng", "cam1.dng", "cam2.dng", "cam3.dng", "disparity.tif", "ground_truth.npz",
                     "scene.json"]  # only the 2-D float array becomes a TIFF
    np.testing.assert_array_equal(tifffile.imread(tmp_path / "s" / "disparity.tif"), gt["disparity"].astype(np.float32))
    meta = json.loads((tmp_path / "s" / "scene.json").read_text())
    assert meta["version"] == rawio.SCENE_VERSION and meta["cfa"] == "GRBG"


# --- errors --------------------------------------------------------------------------------------------------


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.dng"):
        rawio.read_raw(tmp_path / "nope.dng")
    with pytest.raises(FileNotFoundError, match="nope.tif"):
        rawio.read_tiff_raw(tmp_path / "nope.tif", "RGGB")


def test_truncated_dng(tmp_path):
    path = rawio.write_dng(tmp_path / "a.dng", mosaic(), "RGGB", bits=12)
    blob = path.read_bytes()
    path.write_bytes(blob[: len(blob) // 2])
    with pytest.raises(RawFormatError, match=r"a\.dng: LibRaw cannot read it \(LibRawIOError"):
        rawio.read_raw(path)


@pytest.mark.parametrize("content", [b"\x89PNG\r\n\x1a\n" + bytes(300), b"garbage " * 100])
def test_not_a_raw_file(tmp_path, content):
    (tmp_path / "x.png").write_bytes(content)
    with pytest.raises(RawFormatError, match=r"x\.png: LibRaw cannot read it .*Unsupported file format"):
        rawio.read_raw(tmp_path / "x.png")


def test_rgb_tiff_is_not_a_mosaic(tmp_path):
    tifffile.imwrite(tmp_path / "rgb.tif", np.zeros((H, W, 3), np.uint16), photometric="rgb")
    with pytest.raises(RawFormatError, match=r"expected a 2-D Bayer mosaic, got shape \(32, 48, 3\)"):
        rawio.read_tiff_raw(tmp_path / "rgb.tif", "RGGB")


def test_bad_tiffs(tmp_path):
    (tmp_path / "g.tif").write_bytes(b"garbage " * 100)
    with pytest.raises(RawFormatError, match=r"g\.tif: not a readable TIFF"):
        rawio.read_tiff_raw(tmp_path / "g.tif", "RGGB")
    tifffile.imwrite(tmp_path / "odd.tif", np.zeros((31, 48), np.uint16))
    with pytest.raises(RawFormatError, match=r"even height and width.*\(31, 48\)"):
        rawio.read_tiff_raw(tmp_path / "odd.tif", "RGGB")
    tifffile.imwrite(tmp_path / "pages.tif", np.zeros((2, H, W), np.uint16), metadata=None)
    with pytest.raises(RawFormatError, match="single-page TIFF, got 2 pages"):
        rawio.read_tiff_raw(tmp_path / "pages.tif", "RGGB")
    tifffile.imwrite(tmp_path / "a.tif", np.zeros((H, W), np.uint16))
    with pytest.raises(ValueError, match=r"cfa: expected one of .*got 'RGBG'"):
        rawio.read_tiff_raw(tmp_path / "a.tif", "RGBG")
    with pytest.raises(ValueError, match="cfa: required to read the TIFF mosaic"):
        rawio.read_frames([tmp_path / "a.tif"])


def test_xtrans_dng_is_rejected(tmp_path):
    xtrans = (1, 1, 0, 1, 1, 2, 1, 1, 2, 1, 1, 0, 2, 0, 1, 0, 2, 1,
              1, 1, 2, 1, 1, 0, 1, 1, 0, 1, 1, 2, 0, 2, 1, 2, 0, 1)
    tags = [(33421, "H", 2, (6, 6), True), (33422, "B", 36, xtrans, True)]
    write_tiff_dng(tmp_path / "x.dng", mosaic(shape=(36, 48)), tags=tags)
    with pytest.raises(RawFormatError, match=r"x\.dng: expected a 2x2 Bayer CFA, got a 6x6 pattern"):
        rawio.read_raw(tmp_path / "x.dng")


def test_linear_rgb_dng_is_rejected(tmp_path):
    write_tiff_dng(tmp_path / "lin.dng", np.zeros((H, W, 3), np.uint16), photometric=34892)  # LinearRaw
    with pytest.raises(RawFormatError, match=r"lin\.dng: not a Bayer mosaic"):
        rawio.read_raw(tmp_path / "lin.dng")


def test_four_colour_cfa_is_rejected(tmp_path):
    tags = [(33421, "H", 2, (2, 2), True), (33422, "B", 4, (0, 1, 3, 2), True), (50710, "B", 4, (0, 1, 2, 3), True)]
    write_tiff_dng(tmp_path / "q.dng", mosaic(), tags=tags)
    with pytest.raises(RawFormatError, match=r"q\.dng: expected an RGB Bayer sensor .*got 4 colours 'GMCY'"):
        rawio.read_raw(tmp_path / "q.dng")


def test_odd_active_area_is_ambiguous(tmp_path):
    # LibRaw rounds the margins of ActiveArea (1, 1, 31, 47) to 2 but keeps a 29 x 45 visible area.
    tags = [(33421, "H", 2, (2, 2), True), (33422, "B", 4, (0, 1, 1, 2), True), (50829, "I", 4, (1, 1, 31, 47), True)]
    write_tiff_dng(tmp_path / "a.dng", mosaic(), tags=tags)
    with pytest.raises(RawFormatError, match=r"a\.dng: ambiguous visible area"):
        rawio.read_raw(tmp_path / "a.dng")


def test_mismatched_cameras(tmp_path):
    paths = [rawio.write_dng(tmp_path / f"c{i}.dng", mosaic(), "RGGB") for i in range(3)]
    rawio.write_dng(tmp_path / "big.dng", mosaic(shape=(H + 2, W)), "RGGB")
    rawio.write_dng(tmp_path / "bggr.dng", mosaic(), "BGGR")
    with pytest.raises(RawFormatError, match=r"camera 2: size \(34, 48\) differs from camera 0's \(32, 48\)"):
        rawio.read_frames([paths[0], paths[1], tmp_path / "big.dng"])
    with pytest.raises(RawFormatError, match=r"camera 1: CFA BGGR differs from camera 0's RGGB"):
        rawio.read_frames([paths[0], tmp_path / "bggr.dng", paths[2]])


def test_write_dng_rejects_bad_input(tmp_path):
    out = tmp_path / "a.dng"
    with pytest.raises(ValueError, match=r"data: expected a 2-D Bayer mosaic, got shape \(2, 32, 48\)"):
        rawio.write_dng(out, np.zeros((2, H, W), np.uint16), "RGGB")
    with pytest.raises(ValueError, match=r"data: expected even height and width .*\(33, 48\)"):
        rawio.write_dng(out, np.zeros((33, W), np.uint16), "RGGB")
    with pytest.raises(ValueError, match=r"data: expected both sides >= 22 .*got \(16, 48\)"):
        rawio.write_dng(out, np.zeros((16, W), np.uint16), "RGGB")
    with pytest.raises(TypeError, match="data: expected an integer .*got float32"):
        rawio.write_dng(out, np.zeros((H, W), np.float32), "RGGB")
    with pytest.raises(ValueError, match=r"data: expected values in \[0, 4095\] for bits=12, got \[0, 4096\]"):
        rawio.write_dng(out, np.full((H, W), 4096, np.int32) * (np.arange(W) % 2), "RGGB", bits=12)
    with pytest.raises(ValueError, match=r"bits: expected one of \(12, 14, 16\), got 10"):
        rawio.write_dng(out, np.zeros((H, W), np.uint16), "RGGB", bits=10)
    with pytest.raises(ValueError, match=r"cfa: expected one of .*got 'RGB'"):
        rawio.write_dng(out, np.zeros((H, W), np.uint16), "RGB")
    with pytest.raises(ValueError, match=r"black_level: expected a scalar or shape \(2, 2\)"):
        rawio.write_dng(out, np.zeros((H, W), np.uint16), "RGGB", black_level=[1, 2, 3])
    with pytest.raises(ValueError, match=r"white_level: expected an integer in \(0, 4095\] for bits=12"):
        rawio.write_dng(out, np.zeros((H, W), np.uint16), "RGGB", white_level=5000, bits=12)
    assert not out.exists()


def test_scene_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing scene.json"):
        rawio.read_scene(tmp_path)
    raws = [mosaic(seed=i) for i in range(2)]
    folder = rawio.write_scene(tmp_path / "s", raws, "RGGB", black_level=0, ground_truth={}, camera={})
    (folder / "cam1.dng").unlink()
    with pytest.raises(FileNotFoundError, match=r"cam1\.dng: file listed in scene.json is missing"):
        rawio.read_scene(folder)
    (folder / "scene.json").write_text("{not json")
    with pytest.raises(RawFormatError, match=r"scene\.json: not valid JSON"):
        rawio.read_scene(folder)
    (folder / "scene.json").write_text(json.dumps({"format": "something else"}))
    with pytest.raises(RawFormatError, match="expected a 'tpnet-gpu scene' description"):
        rawio.read_scene(folder)
    with pytest.raises(TypeError, match="camera: expected a JSON-serialisable dict"):
        rawio.write_scene(tmp_path / "t", raws, "RGGB", camera={"k": np.zeros(2)})
    with pytest.raises(ValueError, match=r"ground_truth: expected names .*got 'a/b'"):
        rawio.write_scene(tmp_path / "t", raws, "RGGB", ground_truth={"a/b": np.zeros(2)})
