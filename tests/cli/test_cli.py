"""The ``tpnet`` command line (the demo: test_demo.py): `process` reads a scene folder, 4 raws, a stereo pair or a
rig's cameras, bad input ends with a one-line message. Oracles: for `process` the scene folder's own result (the same frames as 4 DNGs), stand-in pipelines that record
their call and return known tile maps (the disparity engine of issue 13 is not there yet), and the argument
rules of docs/rig_file.md §8."""

import signal
import subprocess
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import tifffile
import torch
from PIL import Image

from tpnet_gpu.io import rawio
from tpnet_gpu.cli import main



def test_process_scene_folder_and_bad_inputs(tmp_path, capsys):
    assert main(["render", str(tmp_path / "s"), "--width", "96", "--height", "64", "--supersample", "1"]) == 0
    assert main(["process", str(tmp_path / "s"), "--out", str(tmp_path / "o"), "--device", "cpu",
                 "--backend", "warp"]) == 0
    disparity = tifffile.imread(tmp_path / "o" / "disparity.tif")
    assert disparity.shape == (8, 12) and np.isfinite(disparity).any()
    # The Taichi backend (the CPU default above SMALL_FRAME_PIXELS) gives the same disparities (same math;
    # float32 rounding differs).
    assert main(["process", str(tmp_path / "s"), "--out", str(tmp_path / "t"), "--device", "cpu",
                 "--backend", "taichi"]) == 0
    np.testing.assert_allclose(tifffile.imread(tmp_path / "t" / "disparity.tif"), disparity, atol=1e-3)
    assert (tmp_path / "o" / "texture.png").exists()
    # The same frames as 4 raw files (the quad without a folder): the same disparities.
    cams = [str(tmp_path / "s" / f"cam{i}.dng") for i in range(4)]
    assert main(["process", *cams, "--out", str(tmp_path / "q"), "--device", "cpu", "--backend", "warp"]) == 0
    np.testing.assert_array_equal(tifffile.imread(tmp_path / "q" / "disparity.tif"), disparity)
    capsys.readouterr()
    assert main(["process", str(tmp_path / "nothing")]) == 2
    assert "inputs: no such scene folder" in capsys.readouterr().err


def test_help_lists_subcommands():
    done = subprocess.run([sys.executable, "-m", "tpnet_gpu.cli", "--help"], capture_output=True, text=True)
    assert done.returncode == 0
    for command in ("demo", "process", "render", "inspect", "dataset", "train", "bench"):
        assert command in done.stdout


def test_command_defaults_are_the_configs():
    # Oracle: the config dataclasses, the one home of every default (tpnet_gpu/config.py).
    from tpnet_gpu import cli
    from tpnet_gpu.config import DatasetSpec, TrainConfig

    parser = cli.build_parser()
    data, train = parser.parse_args(["dataset", "out/x"]), parser.parse_args(["train", "out/x"])
    spec, config = DatasetSpec(), TrainConfig()
    assert (data.scenes, data.width, data.height, data.seed, data.supersample, data.test_fraction) == (
        spec.scenes, spec.width, spec.height, spec.seed, spec.supersample, spec.test_fraction)
    assert (train.epochs, train.batch, train.seed, train.w_mode, train.error_scale) == (
        config.epochs, config.batch, config.seed, config.w_mode, config.error_scale)
    # process and demo: the pipeline's config, load_inputs' and run_demo's own defaults; the range: none given
    import inspect

    from tpnet_gpu.config import PipelineConfig
    from tpnet_gpu.demo import run_demo
    from tpnet_gpu.io.stereo_io import load_inputs

    proc, demo = parser.parse_args(["process", "a"]), parser.parse_args(["demo"])
    library = PipelineConfig()
    assert (proc.method, proc.min_confidence, proc.keep_fraction) == (library.method, library.min_confidence,
                                                                      library.keep_fraction)
    signature = inspect.signature(load_inputs).parameters
    assert (proc.colour, proc.reference) == (signature["colour"].default, signature["reference"].default)
    assert proc.min_disparity is None and proc.max_disparity is None and proc.backend is None
    signature = inspect.signature(run_demo).parameters
    assert (demo.out, demo.width, demo.height, demo.seed) == tuple(signature[k].default
                                                                  for k in ("out", "width", "height", "seed"))


# --- process: stereo pairs and rigs ------------------------------------------------------------------------
class RecordingEngine:
    """A Pipeline with the disparity engine's signature: records its call, returns tile maps of known values."""

    calls = []

    def __init__(self, height, width, *, cfa="GRBG", rig=None, min_disparity=0.0, max_disparity=None,
                 weights=None, device=None, backend=None, config=None):
        self.shape = (height, width)
        self.weights = None  # the engine's result: no network (frame_outputs.method)
        self.calls.append(dict(height=height, width=width, cfa=cfa, rig=rig, min_disparity=min_disparity,
                               max_disparity=max_disparity, weights=weights, device=device, backend=backend,
                               config=config))

    def process(self, frames):
        self.calls[-1]["frames"] = np.array(frames)
        self.calls[-1]["torch_threads"] = torch.get_num_threads()
        h, w = self.shape
        tiles = torch.arange(h // 8 * (w // 8), dtype=torch.float32).reshape(h // 8, w // 8)
        texture = torch.arange(4 * h * w, dtype=torch.float32).reshape(4, h, w)
        return SimpleNamespace(disparity=tiles, confidence=tiles + 0.5, texture=texture, pixels=None,
                               pixels_measured=None)


@pytest.fixture
def engine(monkeypatch):
    import tpnet_gpu.pipeline

    RecordingEngine.calls = []
    monkeypatch.setattr(tpnet_gpu.pipeline, "Pipeline", RecordingEngine)
    return RecordingEngine.calls


def _pair(tmp_path, shape=(8, 20)):
    rng = np.random.default_rng(0)
    paths = []
    for name in ("left.png", "right.png"):
        Image.fromarray(rng.integers(0, 256, shape + (3,), dtype=np.uint8)).save(tmp_path / name)
        paths.append(str(tmp_path / name))
    return paths


def test_process_pair_through_the_engine_crops_to_the_image(tmp_path, engine, capsys):
    left, right = _pair(tmp_path)  # 20x8: padded to 24x16, tile grid 3x2, cropped to ceil(8/8) = 1 row
    out = tmp_path / "o"
    assert main(["process", left, right, "--max-disparity", "12.5", "--min-disparity", "-2", "--out", str(out),
                 "--device", "cpu", "--backend", "taichi"]) == 0
    (call,) = engine
    assert (call["height"], call["width"], call["cfa"]) == (16, 24, None)
    assert (call["min_disparity"], call["max_disparity"]) == (-2.0, 12.5)
    assert (call["device"], call["backend"]) == ("cpu", "taichi")
    assert call["rig"].offsets == ((0.0, 0.0), (1.0, 0.0)) and (call["rig"].width, call["rig"].height) == (24, 16)
    assert call["frames"].shape == (2, 16, 24) and call["frames"].dtype == np.float32
    np.testing.assert_array_equal(tifffile.imread(out / "disparity.tif"), [[0.0, 1.0, 2.0]])  # row 0 of the grid
    np.testing.assert_array_equal(tifffile.imread(out / "confidence.tif"), [[0.5, 1.5, 2.5]])
    texture = tifffile.imread(out / "texture.tif")
    np.testing.assert_array_equal(texture, np.arange(4 * 16 * 24, dtype=np.float32).reshape(4, 16, 24)[:, :8, :20])
    assert Image.open(out / "texture.png").size == (20, 8)  # the texture's pixels; disparity.png is a figure
    assert Image.open(out / "disparity.png").size[0] == 640
    assert tifffile.imread(out / "depth.tif")[0, 0] == np.inf  # disparity 0: at infinity
    assert "stereo pair" in capsys.readouterr().out


def test_one_shot_threads_follow_the_frame_size_and_the_backend_is_passed(tmp_path, engine):
    # docs/platform.md §4: a frame of at most SMALL_FRAME_PIXELS (320x240) runs with torch on one thread, a larger
    # one as set; one frame of at most ONE_SHOT_PIXELS (640x480) runs on Warp (its start-up is the shorter), a
    # larger one on the library's choice (None, tested in test_processor.py); --backend is passed as given;
    # torch's count is restored.
    from tpnet_gpu.config import ONE_SHOT_PIXELS, SMALL_FRAME_PIXELS

    assert (SMALL_FRAME_PIXELS, ONE_SHOT_PIXELS) == (320 * 240, 640 * 480)
    threads = torch.get_num_threads()
    for name in ("big", "vga", "larger"):
        (tmp_path / name).mkdir()
    small, big = _pair(tmp_path, (240, 320)), _pair(tmp_path / "big", (240, 328))
    vga, larger = _pair(tmp_path / "vga", (480, 640)), _pair(tmp_path / "larger", (480, 648))
    for images, backend in ((small, []), (big, []), (small, ["--backend", "taichi"]), (vga, []), (larger, [])):
        assert main(["process", *images, "--max-disparity", "4", "--out", str(tmp_path / "o"), "--overwrite",
                     "--no-figures", *backend]) == 0
    assert [(c["height"] * c["width"], c["backend"]) for c in engine] == [
        (76800, "warp"), (78720, "warp"), (76800, "taichi"), (307200, "warp"), (311040, None)]
    assert [c["torch_threads"] for c in engine] == [1, threads, 1, threads, threads]
    assert torch.get_num_threads() == threads


def test_process_rig_of_images_through_the_engine(tmp_path, engine):
    from tpnet_gpu.io import rigfile
    from tpnet_gpu.camera import Rig
    from tpnet_gpu.io.rigfile import write_rig

    rig = write_rig(Rig(offsets=((-0.5, 0.0), (0.5, 0.0), (0.0, 0.75))), tmp_path / "tri.toml")
    (tmp_path / "more").mkdir()
    images = _pair(tmp_path, (16, 16)) + _pair(tmp_path / "more", (16, 16))[:1]
    assert main(["process", *images, "--rig", str(rig), "--max-disparity", "4", "--out", str(tmp_path / "o"),
                 "--reference", "2"]) == 0
    assert engine[0]["rig"].offsets == ((-0.5, -0.75), (0.5, -0.75), (0.0, 0.0))
    assert main(["process", *images[:2], "--rig", "binocular", "--max-disparity", "4", "--reference", "rig",
                 "--out", str(tmp_path / "o"), "--overwrite"]) == 0
    assert engine[1]["rig"].offsets == rigfile.load("binocular").offsets
    assert engine[1]["max_disparity"] == 4.0 and engine[1]["frames"].shape == (2, 16, 16)


ERRORS = [
    (["L", "R"], "--max-disparity: required for ordinary images"),
    (["L", "R", "--max-disparity", "0"], "--max-disparity: expected a positive number of pixels, got '0'"),
    (["L", "R", "--max-disparity", "-3"], "--max-disparity: expected a positive number of pixels, got '-3'"),
    (["L", "R", "--max-disparity", "abc"], "--max-disparity: expected a positive number of pixels, got 'abc'"),
    (["L", "R", "--max-disparity", "nan"], "--max-disparity: expected a positive number of pixels, got 'nan'"),
    (["L", "R", "--max-disparity", "inf"], "--max-disparity: expected a positive number of pixels, got 'inf'"),
    (["L", "R", "--max-disparity", "8", "--min-disparity", "x"], "--min-disparity: expected a number of pixels"),
    (["L", "R", "--max-disparity", "8", "--min-disparity", "8"],
     "--min-disparity: expected less than --max-disparity 8"),
    (["L", "R", "L"], "inputs: expected a scene folder, a stereo pair LEFT RIGHT or 4 raw files"),
    (["L", "R", "L", "--rig", "quad"], "inputs: the rig has 4 cameras, got 3 inputs"),
    (["L", "R", "--rig", "missing.json"], "rig file not found: missing.json"),
    (["L", "R", "--rig", "BADRIG"], "unknown keys ['cameras']"),
    (["L", "R", "--reference", "7", "--max-disparity", "8"], "reference: cam: expected a camera index in 0..1"),
    (["L", "BIG", "--max-disparity", "8"], "left and right: expected the same size, got 20x8"),
    (["L", "NOPE", "--max-disparity", "8"], "right: image file not found"),
    (["L", "TEXT", "--max-disparity", "8"], "right: TEXT: not a readable image"),
    (["a.dng", "b.dng", "--max-disparity", "8"], "left: image file not found: a.dng"),
    (["DNG", "DNG", "--max-disparity", "8"],
     "not an ordinary image; raw files: rawio.read_raw, or `tpnet process --rig FILE`"),
    (["L", "L", "L", "L"], "4 inputs without --rig are a raw quad"),
]


@pytest.mark.parametrize("argv, message", ERRORS, ids=[m[:40] for _, m in ERRORS])
def test_process_argument_errors_are_one_line(tmp_path, monkeypatch, capsys, argv, message):
    monkeypatch.chdir(tmp_path)
    left, _ = _pair(tmp_path)
    Image.fromarray(np.zeros((8, 21), np.uint8)).save(tmp_path / "BIG.png")
    (tmp_path / "TEXT").write_text("hello")
    (tmp_path / "BADRIG.json").write_text('{"cameras": 2}')
    rawio.write_dng(tmp_path / "c.dng", np.zeros((24, 24), np.uint16), "GRBG")
    names = {"L": left, "R": str(tmp_path / "right.png"), "BIG": "BIG.png", "BADRIG": "BADRIG.json", "DNG": "c.dng"}
    assert main(["process", *[names.get(a, a) for a in argv], "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("tpnet process: error: ") and err.count("\n") == 1 and message in err, err


@pytest.mark.parametrize("colour", ["grey", "rgb"])
def test_process_photograph_pair_end_to_end(tmp_path, colour):
    """Oracle: the known shift. An 8-bit photograph (grey ``camera`` or RGB ``astronaut``) shifted by +-d/2
    (exact Fourier shift, per channel) and saved as a PNG pair: ``tpnet process LEFT RIGHT --max-disparity``
    writes the left view's disparity map (the tile grid follows the left camera) with median error <= 0.1 px."""
    import skimage.data
    import tifffile

    from tests.textures import fourier_shift

    if colour == "grey":
        photo = skimage.data.camera().astype(np.float64)[280:400, 150:350]  # the textured lower half
    else:
        photo = np.moveaxis(skimage.data.astronaut().astype(np.float64)[300:420, 100:300], -1, 0)  # (3, H, W)
    d = 4.6
    paths = []
    for name, shift in (("left.png", d / 2), ("right.png", -d / 2)):  # left view: content right of the centre's
        image = np.clip(np.round(fourier_shift(photo, shift, 0.0)), 0, 255).astype(np.uint8)
        Image.fromarray(image if image.ndim == 2 else np.moveaxis(image, 0, -1)).save(tmp_path / name)
        paths.append(str(tmp_path / name))
    out = tmp_path / "o"
    assert main(["process", *paths, "--max-disparity", "10", "--out", str(out), "--device", "cpu"]) == 0
    disparity = tifffile.imread(out / "disparity.tif")
    assert disparity.shape == (15, 25)
    err = disparity[2:-2, 2:-2] - d
    assert np.isfinite(err).mean() > 0.7 and np.nanmedian(np.abs(err)) <= 0.1


# --- issue 16: outputs are never clobbered or half-written ---------------------------------------------------
def _contents(folder):
    """name -> bytes of every file under ``folder`` (directories as None): the oracle of "left as it was"."""
    return {str(p.relative_to(folder)): (None if p.is_dir() else p.read_bytes()) for p in sorted(folder.rglob("*"))}


def _no_leftovers(parent):
    return not [p.name for p in parent.iterdir() if ".tmp-" in p.name or ".old-" in p.name]


def test_issue16_process_into_its_own_scene_folder_is_refused(tmp_path, capsys):
    assert main(["render", str(tmp_path / "s"), "--width", "48", "--height", "32", "--supersample", "1"]) == 0
    before = _contents(tmp_path / "s")
    for extra in ([], ["--overwrite"]):  # never over an input, not even with --overwrite
        assert main(["process", str(tmp_path / "s"), "--out", str(tmp_path / "s"), *extra]) == 2
        assert "--out: expected a folder apart from the inputs" in capsys.readouterr().err
    assert _contents(tmp_path / "s") == before  # the ground-truth disparity.tif/.png are the scene's own


def test_issue16_second_process_into_the_same_out_needs_overwrite(tmp_path, engine, capsys):
    left, right = _pair(tmp_path)
    args = ["process", left, right, "--max-disparity", "4", "--out", str(tmp_path / "o")]
    assert main(args) == 0
    (tmp_path / "o" / "notes.txt").write_text("mine")
    before = _contents(tmp_path / "o")
    capsys.readouterr()
    assert main(args) == 2 and len(engine) == 1  # refused before any work
    assert "--out: expected an empty or new folder (or --overwrite)" in capsys.readouterr().err
    assert _contents(tmp_path / "o") == before
    assert main([*args, "--overwrite"]) == 0 and len(engine) == 2
    assert (tmp_path / "o" / "notes.txt").read_text() == "mine"  # files the output does not replace stay
    assert _no_leftovers(tmp_path)
    assert main(["process", left, right, "--max-disparity", "4", "--out", left]) == 2  # a file: refused early
    assert "--out: expected a folder apart from the inputs" in capsys.readouterr().err


def test_issue16_render_over_an_existing_scene_needs_overwrite(tmp_path, capsys):
    render = ["render", str(tmp_path / "s"), "--width", "48", "--height", "32", "--supersample", "1"]
    assert main(render) == 0
    before = _contents(tmp_path / "s")
    assert main([*render, "--seed", "1"]) == 2
    assert "out: expected an empty or new folder (or --overwrite)" in capsys.readouterr().err
    assert _contents(tmp_path / "s") == before
    assert main([*render, "--seed", "1", "--overwrite"]) == 0
    assert _contents(tmp_path / "s")["cam0.dng"] != before["cam0.dng"] and _no_leftovers(tmp_path)


def test_issue16_failed_write_leaves_the_old_output_whole(tmp_path, engine, monkeypatch, capsys):
    # Before: with texture.png a directory the command exited 2 after the other four files were written. Now
    # a non-empty folder is refused up front, and a write that fails half-way leaves the old folder as it was.
    from tpnet_gpu.io import images

    left, right = _pair(tmp_path)
    out = tmp_path / "o"
    (out / "texture.png").mkdir(parents=True)
    (out / "disparity.tif").write_bytes(b"old")
    before = _contents(out)
    args = ["process", left, right, "--max-disparity", "4", "--out", str(out)]
    assert main(args) == 2 and _contents(out) == before
    real = images.save_png

    def failing(path, image):
        if path.name == "texture.png":
            raise OSError(f"{path}: disk full")
        real(path, image)

    monkeypatch.setattr(images, "save_png", failing)
    assert main([*args, "--overwrite"]) == 2
    assert "disk full" in capsys.readouterr().err
    assert _contents(out) == before and _no_leftovers(tmp_path)
    monkeypatch.setattr(images, "save_png", real)
    assert main([*args, "--overwrite"]) == 0  # the directory in the way is replaced by the new file
    assert (out / "texture.png").is_file() and (out / "disparity.tif").read_bytes() != b"old"


def test_issue16_killed_run_leaves_the_old_output_whole(tmp_path):
    # A run killed (SIGKILL) while writing its third file: the old output folder must be untouched.
    left, right = _pair(tmp_path)
    out = tmp_path / "o"
    out.mkdir()
    (out / "disparity.tif").write_bytes(b"old")
    before = _contents(out)
    script = tmp_path / "killed.py"
    root = Path(__file__).resolve().parents[2]
    script.write_text(textwrap.dedent(f"""
        import os, signal, sys
        sys.path.insert(0, {str(root)!r})
        import tpnet_gpu.pipeline
        from tpnet_gpu.io import images
        from tests.cli.test_cli import RecordingEngine
        from tpnet_gpu.cli import main
        tpnet_gpu.pipeline.Pipeline = RecordingEngine
        real = images.save_png
        def dying(path, image):
            real(path, image)
            os.kill(os.getpid(), signal.SIGKILL)
        images.save_png = dying
        main(["process", {left!r}, {right!r}, "--max-disparity", "4", "--out", {str(out)!r}, "--overwrite"])
    """))
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300)
    assert done.returncode == -signal.SIGKILL, done.stderr[-2000:]
    assert _contents(out) == before
