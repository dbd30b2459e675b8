"""The ``tpnet process`` inputs (tpnet_gpu/io/stereo_io.py, docs/rig_file.md §7, §8): which inputs make which frames
and rig, and the one call into the pipeline (``make_pipeline``).

Oracles: the files written to tmp_path (DNG mosaics through ``rawio.write_dng``, images through Pillow), the rig
files' own numbers, and stand-in ``Pipeline`` classes with the disparity engine's signature (issue 13) and
today's, which record how they are called.
"""

from dataclasses import replace

import numpy as np
import pytest
from PIL import Image

from tpnet_gpu import tables
from tpnet_gpu.io import rawio
from tpnet_gpu.io import rigfile
from tpnet_gpu.camera import Rig
from tpnet_gpu.io.stereo_io import Frames, Inputs, fit_rig, load_inputs, load_stereo_pair, make_pipeline

RNG = np.random.default_rng(3)
CALIBRATED = Rig(width=40, height=24, offsets=((-0.5, 0.0), (0.5, 0.0)), distortion=(0.01,) + (0.0,) * 6)


def _png(path, shape=(21, 34)):
    Image.fromarray(RNG.integers(0, 256, shape, dtype=np.uint8)).save(path)
    return path


def _dng(path, shape=(26, 34)):
    return rawio.write_dng(path, RNG.integers(64, 4095, shape).astype(np.uint16), "RGGB", black_level=64,
                           white_level=4095, bits=12)


def test_pair_without_rig_is_the_left_referenced_binocular(tmp_path):
    inputs = load_inputs([_png(tmp_path / "l.png"), _png(tmp_path / "r.png")])
    assert inputs.kind == "pair" and inputs.frames.cfa is None and inputs.frames.frames.shape == (2, 24, 40)
    binocular = rigfile.load("binocular")
    assert inputs.rig.offsets == ((0.0, 0.0), (1.0, 0.0))
    assert (inputs.rig.width, inputs.rig.height) == (40, 24)  # an ideal rig takes the padded size
    assert replace(inputs.rig, width=binocular.width, height=binocular.height, offsets=binocular.offsets) == binocular
    as_given = load_inputs([tmp_path / "l.png", tmp_path / "r.png"], reference="rig")
    assert as_given.rig.offsets == binocular.offsets
    assert load_inputs([tmp_path / "l.png", tmp_path / "r.png"], reference="1").rig.offsets == ((-1.0, 0.0), (0.0, 0.0))


def test_rig_with_images_and_raws(tmp_path):
    pngs = [_png(tmp_path / f"c{i}.png") for i in range(8)]
    inputs = load_inputs(pngs, rig="two_quads")
    assert inputs.kind == "images" and inputs.rig.offsets == rigfile.load("two_quads").offsets  # not re-referenced
    assert inputs.frames.frames.shape == (8, 24, 40)
    dngs = [_dng(tmp_path / f"c{i}.dng") for i in range(2)]
    raw = load_inputs(dngs, rig=rigfile.examples()["binocular"])
    assert raw.kind == "raw" and raw.frames.cfa == "RGGB" and raw.frames.frames.shape == (2, 32, 40)
    assert (raw.frames.white_level, raw.frames.bits, raw.frames.size) == (4095.0 - 64.0, 12, (26, 34))
    frame = rawio.read_raw(dngs[1]).normalised()
    np.testing.assert_array_equal(raw.frames.frames[1, :26, :34], frame)
    np.testing.assert_array_equal(raw.frames.frames[1, 26:, :34], np.tile(frame[24:26], (3, 1)))  # CFA kept
    assert raw.rig.offsets == rigfile.load("binocular").offsets  # a raw pair keeps the rig's reference
    tif = tmp_path / "m.tif"
    import tifffile

    tifffile.imwrite(tif, RNG.integers(0, 255, (16, 16), dtype=np.uint8))
    assert load_inputs([tif, tif], rig="binocular", cfa="GRBG").kind == "raw"  # a TIFF with --cfa is a mosaic
    assert load_inputs([tif, tif], rig="binocular").kind == "pair"  # without it, an image


def test_raw_quad_without_rig(tmp_path):
    dngs = [_dng(tmp_path / f"c{i}.dng", (32, 48)) for i in range(4)]
    inputs = load_inputs(dngs)
    assert inputs.kind == "raw" and inputs.rig == Rig(width=48, height=32) and inputs.frames.padded == (32, 48)


BAD = [
    (lambda t: [t / "a.png"] * 3, {}, "expected a scene folder, a stereo pair LEFT RIGHT or 4 raw"),
    (lambda t: [t / "a.png"] * 3, {"rig": "quad"}, "inputs: the rig has 4 cameras, got 3 inputs"),
    (lambda t: [t / "a.png", t / "x.dng"], {}, "right: image file not found: "),
    (lambda t: [t / "a.png"] * 4, {}, "4 inputs without --rig are a raw quad"),
    (lambda t: [t / "x.dng", t / "a.png"], {"rig": "binocular"}, "expected all raw files or all ordinary images"),
    (lambda t: [t / "nothing"], {}, "inputs: no such scene folder"),
    (lambda t: [t / "a.png"] * 2, {"rig": "octagon"}, "nor a shipped example"),
    (lambda t: [t / "a.png"] * 2, {"reference": "left"}, "reference: expected 'auto', 'rig' or a camera index"),
    (lambda t: [t / "a.png"] * 2, {"reference": "2"}, "reference: cam: expected a camera index in 0..1, got 2"),
    (lambda t: [t / "a.png"] * 2, {"rig": CALIBRATED}, "describes sensors of 40x24, the inputs are 34x21"),
]


@pytest.mark.parametrize("paths, kw, message", BAD, ids=[m[:40] for _, _, m in BAD])
def test_bad_inputs_say_what_would_do(tmp_path, paths, kw, message):
    _png(tmp_path / "a.png")
    with pytest.raises((ValueError, FileNotFoundError)) as err:
        load_inputs(paths(tmp_path), **kw)
    assert message in str(err.value)


def test_fit_rig(tmp_path):
    pair = load_stereo_pair(_png(tmp_path / "a.png", (24, 40)), tmp_path / "a.png")
    assert fit_rig(CALIBRATED, pair) is CALIBRATED  # the frames' size, no padding: as it is
    odd = load_stereo_pair(_png(tmp_path / "b.png", (23, 40)), tmp_path / "b.png")
    with pytest.raises(ValueError, match="describes sensors of 40x24, the inputs are 40x23"):
        fit_rig(CALIBRATED, odd)
    with pytest.raises(ValueError, match="needs inputs whose sides are multiples of 8"):
        fit_rig(replace(CALIBRATED, height=23, _cache={}), odd)
    with pytest.raises(ValueError, match="rig: describes 4 cameras, got 2 inputs"):
        fit_rig(Rig(), pair)


class EnginePipeline:
    """Stand-in with the disparity engine's signature (issue 13)."""

    calls = []

    def __init__(self, height, width, *, cfa="GRBG", rig=None, min_disparity=None, max_disparity=None,
                 weights=None, device=None, backend=None, config=None):
        self.calls.append(dict(height=height, width=width, cfa=cfa, rig=rig, min_disparity=min_disparity,
                               max_disparity=max_disparity, device=device, backend=backend, config=config))


@pytest.fixture
def pipeline(monkeypatch):
    import tpnet_gpu.pipeline

    def use(cls):
        cls.calls = []
        monkeypatch.setattr(tpnet_gpu.pipeline, "Pipeline", cls)
        return cls.calls

    return use


def _inputs(height, width, cfa, rig, kind):
    cams = rig.cams
    frames = Frames(np.zeros((cams, height, width), np.float32), (height, width), 255.0, 8, cfa, ())
    return Inputs(frames, rig, kind)


def test_make_pipeline_with_the_engine(pipeline):
    calls = pipeline(EnginePipeline)
    rig = replace(rigfile.load("binocular").referenced_to(0), width=40, height=24, _cache={})
    from tpnet_gpu.pipeline import PipelineConfig

    pair = _inputs(24, 40, None, rig, "pair")
    make_pipeline(pair, min_disparity=-1.0, max_disparity=12.5, device="cpu", backend="warp")
    assert calls == [dict(height=24, width=40, cfa=None, rig=rig, min_disparity=-1.0, max_disparity=12.5,
                          device="cpu", backend="warp", config=PipelineConfig())]
    make_pipeline(pair, max_disparity=4.0, keep_fraction=0.5, cross_check=False)
    assert calls[-1]["config"] == PipelineConfig(keep_fraction=0.5, cross_check=False)
    assert calls[-1]["min_disparity"] is None  # not given: the engine's default (0)
    quad = Rig(width=48, height=32)
    make_pipeline(_inputs(32, 48, "GRBG", quad, "raw"), device=None, backend=None)
    assert calls[-1]["max_disparity"] is None  # not given: Pipeline takes None as the engine's default (the rig's)


def test_make_pipeline_refuses_ordinary_images_without_a_range(pipeline):
    """Ordinary images' rig is made up (focal length, baseline unknown): the library, not only the CLI, wants
    their largest disparity - and builds nothing without it."""
    calls = pipeline(EnginePipeline)
    rig = replace(rigfile.load("binocular").referenced_to(0), width=40, height=24, _cache={})
    for kind in ("pair", "images"):
        with pytest.raises(ValueError, match=r"max_disparity: required for ordinary images"):
            make_pipeline(_inputs(24, 40, None, rig, kind))
    assert calls == []


