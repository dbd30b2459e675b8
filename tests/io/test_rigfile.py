"""Rig files (tpnet_gpu/io/rigfile.py, docs/rig_file.md) and ``Rig.referenced_to``.

Oracles: the ``Rig`` itself (a file written and read back compares equal field by field), the shipped examples'
numbers as the brief and rig_file.md §4 state them, the document's own JSON and TOML examples, hand-written bad
files (each message must name the field, what was expected and what came), and the closed forms of the ideal
rig for the reference camera (camera i sees c - d r_i, geometry_and_lma.md A.2).
"""

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from tpnet_gpu import tables
from tpnet_gpu.io import rigfile
from tpnet_gpu.camera import Rig
from tpnet_gpu.io.rigfile import RigFileError, read_rig, rig_from_dict, write_rig

DOC = Path(__file__).resolve().parents[2] / "docs" / "rig_file.md"
CALIBRATED = Rig(width=640, height=480, pixel_size_mm=0.003, focal_mm=6.0, baseline_mm=120.0,
                 offsets=((-0.5, 0.0), (0.5, 0.0), (0.0, 0.75)),
                 distortion=(0.02, -0.05, 0.03, 0.0, -0.004, 0.0, 1e-05), distortion_radius_mm=1.1,
                 principal_points=((321.5, 239.25), (318.0, 241.0), (320.0, 240.0)),
                 extrinsics=tuple(1e-4 * (i + 1) for i in range(13)), rolls_deg=(0.1, -0.2, 0.05))
MINIMAL = {"width": 64, "height": 48, "pixel_size_mm": 0.0022, "focal_mm": 4.5, "baseline_mm": 258,
           "offsets": [[-0.5, 0], [0.5, 0]]}


@pytest.mark.parametrize("suffix", [".json", ".toml"])
@pytest.mark.parametrize("rig", [Rig(), CALIBRATED, Rig(offsets=((-0.5, 0.0), (0.5, 0.0)))],
                         ids=["quad", "calibrated", "pair"])
def test_round_trip(tmp_path, rig, suffix):
    path = write_rig(rig, tmp_path / f"rig{suffix}", description='a "test" rig \u00e9')
    back = read_rig(path)
    assert back == rig  # every field, floats bit-exact (repr round-trips)
    assert read_rig(write_rig(rig, tmp_path / f"again{suffix}")) == rig


def test_written_json_is_the_documented_form(tmp_path):
    data = json.loads(write_rig(CALIBRATED, tmp_path / "r.json", description="x").read_text())
    assert list(data)[:3] == ["format", "version", "description"]
    assert data["format"] == "tpnet-gpu rig" and data["version"] == 1
    assert data["principal_points"] == [list(p) for p in CALIBRATED.principal_points]
    assert "principal_points" not in json.loads(write_rig(Rig(), tmp_path / "q.json").read_text())


def test_shipped_examples():
    found = rigfile.examples()
    assert set(found) == {"quad", "binocular", "two_quads"}
    rigs = {name: read_rig(path) for name, path in found.items()}
    assert rigs["quad"] == Rig()  # the project's quad (258 mm, 2592x1936, ideal)
    assert rigs["binocular"].offsets == ((-0.5, 0.0), (0.5, 0.0))
    two = rigs["two_quads"].offsets_array()
    np.testing.assert_array_equal(two[:4], np.asarray(tables.QUAD_OFFSETS) + (-1.0, 0.0))
    np.testing.assert_array_equal(two[4:], np.asarray(tables.QUAD_OFFSETS) + (1.0, 0.0))
    for name, rig in rigs.items():
        assert rig.is_ideal() and (rig.width, rig.height, rig.baseline_mm) == (2592, 1936, 258.0), name
        assert rigfile.load(name) == rig  # a shipped example by name
        # each file is exactly what write_rig writes for it (so they stay in the documented form)
        assert rigfile._json(rigfile.rig_to_dict(rig, json.loads(found[name].read_text())["description"])) == \
            found[name].read_text()


def test_document_examples_are_the_binocular_rig():
    text = DOC.read_text(encoding="utf-8")
    blocks = dict(re.findall(r"```(json|toml)\n(.*?)```", text, re.S))
    binocular = read_rig(rigfile.examples()["binocular"])
    assert rig_from_dict(json.loads(blocks["json"])) == binocular
    assert blocks["json"] == rigfile.examples()["binocular"].read_text()
    import tomllib

    assert rig_from_dict(tomllib.loads(blocks["toml"])) == binocular  # optional fields default to the JSON's


def test_defaults_of_optional_fields():
    rig = rig_from_dict(MINIMAL)
    assert rig.distortion == (0.0,) * 7 and rig.extrinsics == (0.0,) * 13
    assert rig.principal_points is None and rig.rolls_deg is None
    assert rig.distortion_radius_mm == pytest.approx(64 * 0.0022 / 2)  # half the sensor width
    assert isinstance(rig.baseline_mm, float) and rig.offsets == ((-0.5, 0.0), (0.5, 0.0))


def _with(**changes):
    data = dict(MINIMAL)
    for key, value in changes.items():
        if value is _with:
            data.pop(key)
        else:
            data[key] = value
    return data


BAD = [
    (_with(fov=60), "unknown keys ['fov']"),
    (_with(offsets=_with), "missing keys ['offsets']"),
    (_with(format="other"), "format: expected 'tpnet-gpu rig', got 'other'"),
    (_with(version=2), "version: expected an integer 1..1, got 2"),
    (_with(width=0), "width: expected a positive integer number of pixels, got 0"),
    (_with(height=480.0), "height: expected a positive integer number of pixels, got 480.0"),
    (_with(width=True), "width: expected a positive integer number of pixels, got True"),
    (_with(baseline_mm=0), "baseline_mm: expected a positive length in mm, got 0"),
    (_with(focal_mm=-4.5), "focal_mm: expected a positive length in mm, got -4.5"),
    (_with(pixel_size_mm="2.2um"), "pixel_size_mm: expected a number, got '2.2um'"),
    (_with(distortion_radius_mm=math.nan), "distortion_radius_mm: expected a finite number, got nan"),
    (_with(offsets=[[-0.5, 0], [math.nan, 0]]), "offsets[1][0]: expected a finite number, got nan"),
    (_with(offsets=[[-0.5, 0], [0.5, 0, 1]]), "offsets[1]: expected 2 numbers (x, y), got 3"),
    (_with(offsets=[[0, 0]]), "offsets: expected at least 2 cameras (x, y), got 1"),
    (_with(offsets="left right"), "offsets: expected a list of (x, y) rows"),
    (_with(distortion=[0.1]), "distortion: expected 7 terms (C, B, A, A5, A6, A7, A8), got 1"),
    (_with(extrinsics=[0.0] * 12), "extrinsics: expected 13 terms"),
    (_with(extrinsics=[0.0] * 12 + [math.inf]), "extrinsics[12]: expected a finite number, got inf"),
    (_with(principal_points=[[32, 24]]), "principal_points: expected 2 (x, y) rows, one per camera, got 1"),
    (_with(rolls_deg=[0.0, 0.0, 0.0]), "rolls_deg: expected 2 angles (degrees), one per camera, got 3"),
    (_with(description=3), "description: expected a string, got 3"),
    ([1, 2], "expected a table (JSON object) of rig fields, got list"),
]


@pytest.mark.parametrize("data, message", BAD, ids=[m.split(":")[0][:30] for _, m in BAD])
def test_bad_fields_are_named(data, message):
    with pytest.raises(RigFileError) as err:
        rig_from_dict(data, "my.json")
    assert str(err.value).startswith("my.json: ") and message in str(err.value)


def test_bad_files(tmp_path):
    (tmp_path / "nan.json").write_text(json.dumps(_with(baseline_mm=math.nan)))  # JSON's NaN extension
    with pytest.raises(RigFileError, match=r"nan.json: baseline_mm: expected a finite number, got nan"):
        read_rig(tmp_path / "nan.json")
    (tmp_path / "inf.toml").write_text("width = 64\nheight = 48\npixel_size_mm = inf\nfocal_mm = 4.5\n"
                                       "baseline_mm = 258\noffsets = [[-0.5, 0], [0.5, 0]]\n")
    with pytest.raises(RigFileError, match="pixel_size_mm: expected a finite number, got inf"):
        read_rig(tmp_path / "inf.toml")
    (tmp_path / "broken.json").write_text('{"width": 64,')
    with pytest.raises(RigFileError, match=r"broken.json: not valid JSON \(.*line 1"):
        read_rig(tmp_path / "broken.json")
    (tmp_path / "broken.toml").write_text("width = = 3")
    with pytest.raises(RigFileError, match="broken.toml: not valid TOML"):
        read_rig(tmp_path / "broken.toml")
    (tmp_path / "binary.json").write_bytes(b"\xff\xfe\x00")
    with pytest.raises(RigFileError, match="not a text file"):
        read_rig(tmp_path / "binary.json")
    with pytest.raises(RigFileError, match=r"path: expected a \.json or \.toml rig file, got 'rig.yaml'"):
        read_rig(tmp_path / "rig.yaml")
    with pytest.raises(FileNotFoundError, match="rig file not found"):
        read_rig(tmp_path / "missing.json")
    with pytest.raises(FileNotFoundError, match="nor a shipped example: binocular, quad, two_quads"):
        rigfile.resolve("octagon")


# issue 40 item 5: numbers no camera has. The oracle is the physics each one breaks, checked on a Rig built
# without the file's bounds: depth or rays that are not finite.
CRAFTED = [
    ({"pixel_size_mm": 1e-320}, "pixel_size_mm: expected a value in [0.0001, 1]", "depth"),
    ({"focal_mm": 1e308}, "focal_mm: expected a value in [0.1, 10000]", "depth"),
    ({"extrinsics": [1e300] * 13}, "extrinsics[0]: expected a value in [-1, 1]", "views"),
    ({"width": 10**6}, "width: expected a value in [1, 65535]", None),
    ({"offsets": [[-0.5, 0.0], [1e200, 0.0]]}, "offsets[1][0]: expected a value in [-100, 100]", "views"),
    ({"distortion": [0, 0, 0, 0, 0, 0, 1e30]}, "distortion[6]: expected a value in [-10, 10]", "views"),
]


@pytest.mark.parametrize("change, message, broken", CRAFTED, ids=[m.split(":")[0] for _, m, _ in CRAFTED])
def test_numbers_no_camera_has_are_refused_naming_the_field(change, message, broken):
    data = _with(**change)
    with pytest.raises(RigFileError) as err:
        rig_from_dict(data, "my.json")
    assert str(err.value).startswith("my.json: ") and message in str(err.value) and "physical bounds" in str(err.value)
    if broken is None:
        return
    fields = {k: (tuple(map(tuple, v)) if k == "offsets" else tuple(v) if isinstance(v, list) else v)
              for k, v in data.items() if k not in ("format", "version", "description")}
    raw = Rig(**fields)  # what the pipeline would have run with before the bounds
    corners = np.array([[0.0, 0.0], [raw.width, raw.height]])
    try:
        with np.errstate(all="ignore"):
            value = (raw.image_to_world(corners, np.full(2, 4.0)) if broken == "depth"
                     else raw.port_coordinates(corners, np.full(2, float(raw.width))))
    except ValueError as exc:  # the lens model itself gives up (distortion not invertible)
        assert "distortion" in str(exc)
        return
    assert not np.isfinite(value).all() or np.abs(value).max() > 1e12  # the physics it would break


def test_huge_integers_and_in_bound_combinations_are_refused(tmp_path):
    (tmp_path / "digits.json").write_text('{"width": ' + "1" * 5000 + "}")
    with pytest.raises(RigFileError, match=r"digits.json: not a rig file: JSON with Exceeds the limit"):
        read_rig(tmp_path / "digits.json")
    (tmp_path / "digits.toml").write_text("width = " + "1" * 5000 + "\n")
    with pytest.raises(RigFileError, match=r"digits.toml: not a rig file: TOML with"):
        read_rig(tmp_path / "digits.toml")
    for bounds in ({"pixel_size_mm": 1.0, "focal_mm": 0.1}, {"pixel_size_mm": 1e-4, "focal_mm": 1e4}):
        with pytest.raises(RigFileError, match="focal_mm / pixel_size_mm: expected a value in"):
            rig_from_dict(_with(**bounds), "my.json")


def test_writing_refuses_what_reading_would(tmp_path):
    with pytest.raises(RigFileError, match=r"rig: offsets\[0\]\[0\]: expected a finite number, got nan"):
        write_rig(Rig(offsets=((math.nan, 0.0), (0.5, 0.0))), tmp_path / "r.json")
    with pytest.raises(RigFileError, match="rolls_deg: expected 4 angles"):
        write_rig(Rig(rolls_deg=(1.0,)), tmp_path / "r.toml")
    assert not list(tmp_path.iterdir())


# --- the reference camera -----------------------------------------------------------------------------------
@pytest.mark.parametrize("name, cam", [("binocular", 0), ("binocular", 1), ("quad", 2), ("two_quads", 5)])
def test_referenced_camera_sees_the_tile_grid(name, cam):
    # Oracle: the ideal rig's closed form, camera i at c - d r_i; referenced, camera cam has r = 0, so its tile
    # centres are the grid (8 tx + 4, 8 ty + 4) exactly, and every camera moves by d r_cam.
    rig = replace_size(rigfile.load(name), 96, 64)
    ref = rig.referenced_to(cam)
    np.testing.assert_array_equal(ref.offsets_array()[cam], (0.0, 0.0))
    d = np.random.default_rng(cam).uniform(-3, 40, (8, 12))
    ty, tx = np.meshgrid(np.arange(8), np.arange(12), indexing="ij")
    grid = np.stack([8.0 * tx + 4, 8.0 * ty + 4], -1).reshape(-1, 2)
    centres = ref.tile_centres(d)
    np.testing.assert_array_equal(centres[:, cam], grid)
    shift = d.reshape(-1, 1, 1) * rig.offsets_array()[cam]
    np.testing.assert_allclose(centres, rig.tile_centres(d) + shift, rtol=0, atol=1e-12)


def replace_size(rig, width, height):
    from dataclasses import replace

    return replace(rig, width=width, height=height, distortion_radius_mm=width * rig.pixel_size_mm / 2, _cache={})


def test_reference_keeps_every_world_point_in_every_camera():
    # Oracle: the calibrated rig itself. World points move with the origin (to camera cam's lens); each one's
    # pixel in every camera, the rays of every pixel, disparity <-> distance and pair directions stay the same.
    cam = 2
    ref = CALIBRATED.referenced_to(cam)
    lens = CALIBRATED.lens_positions()[cam]
    np.testing.assert_allclose(ref.lens_positions(), CALIBRATED.lens_positions() - lens, atol=1e-12)
    rng = np.random.default_rng(1)
    points = np.stack([rng.uniform(-2e3, 2e3, 20), rng.uniform(-1e3, 1e3, 20), rng.uniform(-6e4, -5e3, 20)], -1)
    pixels, d = CALIBRATED.world_to_image(points)
    ref_pixels, ref_d = ref.world_to_image(points - lens)
    np.testing.assert_allclose(ref_d, d, rtol=1e-12)
    np.testing.assert_allclose(ref.port_coordinates(ref_pixels, ref_d), CALIBRATED.port_coordinates(pixels, d),
                               rtol=0, atol=1e-7)
    np.testing.assert_allclose(ref.image_to_world(ref_pixels, ref_d) + lens, points, rtol=1e-9)
    px = rng.uniform(0, 640, (5, 2))
    np.testing.assert_array_equal(ref.pixel_rays(1, px), CALIBRATED.pixel_rays(1, px))
    assert ref.distance(10.0) == CALIBRATED.distance(10.0)
    offsets, ref_offsets = CALIBRATED.offsets_array(), ref.offsets_array()
    np.testing.assert_allclose(ref_offsets[1] - ref_offsets[0], offsets[1] - offsets[0], atol=1e-15)
    assert (ref.distortion, ref.principal_points, ref.extrinsics, ref.rolls_deg) == (
        CALIBRATED.distortion, CALIBRATED.principal_points, CALIBRATED.extrinsics, CALIBRATED.rolls_deg)


def test_reference_of_a_pair_is_left_view_and_bad_indices():
    left = rigfile.load("binocular").referenced_to(0)
    assert left.offsets == ((0.0, 0.0), (1.0, 0.0))  # the right camera sees the left's (x, y) at (x - d, y)
    assert left.referenced_to(0) == left
    for bad in (2, -1, True, 1.0):
        with pytest.raises(ValueError, match=r"cam: expected a camera index in 0..1"):
            left.referenced_to(bad)
