"""The pipeline and the ``tpnet process`` command really use TPNET: tests that an identity network fails.

Scene: the demo scene, 320x240 (40x30 tiles), photon and read noise on, seed 7 (not a held-out bench seed,
those are 10000+), rendered once for the module. Oracles: the renderer's per-tile ground truth
(``Rendered.tile_disparity``) for accuracy; TPNET run by hand from the public pieces (a tile processor with the
weights' correlation settings, ``infer.infer``, then its context step ``net.context.context_step`` with the engine's
strength; the step has its own oracle tests in test_context.py) for "the pipeline returns what the network says".
The fixture takes ~2.6 s in the full suite on 2 idle cores (~5 s run alone: it then also pays the Warp and
Taichi start-up), the tests < 1 s each: not marked slow.
"""

import numpy as np
import pytest
import tifffile
import torch

from tpnet_gpu import evaluation
from tpnet_gpu.camera import Rig
from tpnet_gpu.cli import main
from tpnet_gpu.disparity.engine import REFERENCE_LEVEL
from tpnet_gpu.net import infer
from tpnet_gpu.net.context import context_step
from tpnet_gpu.pipeline import Pipeline, load_frames
from tpnet_gpu.processor import TileProcessor
from tpnet_gpu.scenes import Sensor, demo_scene, render
from tpnet_gpu.scenes.folder import save

WIDTH, HEIGHT, SEED = 320, 240, 7
# RMSE(network) / RMSE(initial targets) on the flat tiles where the initial target is within 1 px of the ground
# truth. Measured with the shipped weights and the context step on this scene (demo, 320x240, noise on), seeds
# 1-10: v6 with the 5x5 step 0.30-0.43 (seed 7: 0.296), an identity network followed by that step 0.52-0.60
# (seed 7: 0.572), without the step exactly 1.0. Before (the 3x3 step): v5 0.33-0.47 (seed 7: 0.335); v4
# 0.37-0.50 (seed 7: 0.37; the network alone: 0.54-0.63); the identity network and the step 0.60-0.73.
MAX_RATIO = 0.45
MIN_TILES = 300  # flat tiles with the initial within 1 px: ~420 on this scene


@pytest.fixture(scope="module")
def scene():
    """The rendered scene, its black-subtracted frames and the pipeline's result on them (NumPy copies), with the
    engine's strength (its run again on the frames: deterministic)."""
    rig = Rig(width=WIDTH, height=HEIGHT)
    rendered = render(demo_scene(rig, seed=SEED), rig, sensor=Sensor(), supersample=2, seed=SEED)
    frames = rendered.raws.astype(np.float32) - rendered.sensor.black_level
    pipe = Pipeline(HEIGHT, WIDTH, cfa=rendered.sensor.cfa, device="cpu")
    result = pipe.process(frames)
    out = {name: getattr(result, name).cpu().numpy() for name in ("disparity", "initial", "search")}
    out["strength"] = pipe.engine.run(frames).strength.cpu().numpy()
    return rendered, frames, out


def network_gain(rendered, disparity: np.ndarray, initial: np.ndarray) -> tuple[float, int]:
    """RMSE(disparity) / RMSE(initial) against the ground truth, and the number of tiles, over the flat tiles
    (tpnet_gpu.evaluation) where the initial target is within 1 px of the ground truth."""
    gt = rendered.tile_disparity
    flat = evaluation.tile_classes(gt, rendered.tile_confidence, rendered.tile_spread)["flat"]
    tiles = flat & evaluation.reference_inliers(initial, gt)
    net = evaluation.error_stats(disparity, gt, tiles)
    assert net["coverage"] == 1.0  # the network answers wherever the initial target was measured
    return net["rmse"] / evaluation.error_stats(initial, gt, tiles)["rmse"], int(tiles.sum())


def moved_share(disparity: np.ndarray, initial: np.ndarray) -> float:
    """The share of the measured tiles (finite ``initial``) where ``disparity`` differs by more than 1e-3 px."""
    measured = np.isfinite(initial)
    return float(np.mean(np.abs(disparity - initial)[measured] > 1e-3))


def test_network_beats_its_initial_targets(scene):
    """Oracle: the rendered ground truth. Tolerance: RMSE(pipeline) <= MAX_RATIO x RMSE(initial) on >= 300 flat
    tiles where the initial is within 1 px (measured above; an identity network and the step give 0.52-0.60)."""
    rendered, _, result = scene
    ratio, tiles = network_gain(rendered, result["disparity"], result["initial"])
    assert tiles >= MIN_TILES
    assert ratio <= MAX_RATIO, f"network RMSE {ratio:.3f} x the initial targets' on {tiles} flat tiles"


def test_pipeline_returns_the_networks_output(scene):
    """Oracle: TPNET run by hand on a tile processor with the weights' correlation settings, at the pipeline's
    initial targets (the first stage's answer where unmeasured, as the pipeline feeds them), then the context step
    on the measured tiles with the engine's strength. Tolerance: 1e-4 px where measured; the
    network moves >= 90 % of the measured tiles by more than 1e-3 px (measured: 99 % of the 77 % measured;
    the hand-run network matches to 0 px on the same backend, 2e-5 px across Warp and Taichi)."""
    rendered, frames, result = scene
    initial = result["initial"]
    measured = np.isfinite(initial)
    tp = TileProcessor(HEIGHT, WIDTH, cfa=rendered.sensor.cfa, config=infer.correlation(), device="cpu")
    target = torch.from_numpy(np.where(measured, initial, result["search"]).astype(np.float32))
    # the engine scales the frames to a reference mean level before correlating (tpnet_gpu/disparity/engine.py)
    scaled = frames * np.float32(REFERENCE_LEVEL / np.abs(frames).mean())
    layers = tp.process(scaled, target).layers
    network = infer.infer(infer.load(), layers, target, grid=(tp.tiles_y, tp.tiles_x))
    expected = context_step(torch.where(torch.from_numpy(measured), network, torch.tensor(float("nan"))),
                            torch.from_numpy(result["strength"])).numpy()
    np.testing.assert_allclose(result["disparity"][measured], expected[measured], rtol=0, atol=1e-4)
    assert np.isnan(result["disparity"][~measured]).all()
    assert measured.mean() > 0.5, f"{measured.mean():.0%} of the tiles measured"
    assert moved_share(result["disparity"], initial) >= 0.9


def test_identity_network_fails_the_accuracy_criterion(scene, monkeypatch):
    """The accuracy test can fail: with ``infer.infer`` returning its input (patched before the pipeline is
    built: it keeps the function it found) the pipeline's disparity is its initial targets after the context step
    and the ratio of test_network_beats_its_initial_targets is 0.57 (> 0.45)."""
    rendered, frames, _ = scene
    monkeypatch.setattr(infer, "infer", lambda model, layers, target, grid=None, active=None: target.clone())
    result = Pipeline(HEIGHT, WIDTH, cfa=rendered.sensor.cfa, device="cpu").process(frames)
    disparity, initial = result.disparity.cpu().numpy(), result.initial.cpu().numpy()
    ratio, _ = network_gain(rendered, disparity, initial)
    assert ratio > MAX_RATIO


def test_cli_process_writes_the_networks_disparity(scene, tmp_path):
    """Oracle: the pipeline's disparity on the same frames (the scene written as a folder and read back
    unchanged), on the same backend (the library's default for this small frame, Warp, on both sides: the twin
    kernels' float differences move a few tiles by up to ~1e-4 px after refinement and the network). Tolerance:
    1e-6 px, NaN
    where the pipeline has NaN; and the file is not the initial targets (>= 90 % of the measured tiles differ by
    more than 1e-3 px)."""
    rendered, frames, result = scene
    folder = save(rendered, tmp_path / "scene", previews=False)
    np.testing.assert_array_equal(load_frames(folder)[0], frames)
    assert main(["process", str(folder), "--out", str(tmp_path / "out"), "--device", "cpu"]) == 0
    written = tifffile.imread(tmp_path / "out" / "disparity.tif")
    np.testing.assert_allclose(written, result["disparity"], rtol=0, atol=1e-6, equal_nan=True)
    assert moved_share(written, result["initial"]) >= 0.9
