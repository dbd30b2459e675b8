"""The pipeline's network on rigs other than the quad (tpnet_gpu/pipeline.py, network.md §11): it picks the
weights trained for its rig's layer lags, refuses others with a message naming both, and runs without the
network where none fit. Oracles: the lags written in the weights' recipes, the engine's own result, and the
renderer's ground truth (the demo scene rendered by each rig, 320x240, seed 3)."""

import json
import logging
from dataclasses import replace

import numpy as np
import pytest
import torch

from tests.disparity.test_engine import MISALIGNED, RIGS, flat_stats, rendered_scene
from tpnet_gpu.io import rigfile
from tpnet_gpu.net import infer
from tpnet_gpu.net.model import TPNet
from tpnet_gpu.pipeline import Pipeline, PipelineConfig
from tpnet_gpu.scenes import Scene, Sky, plane, render
from tpnet_gpu.scenes import textures as tx

H, W = 64, 96
D = 3.3
NO_TEXTURES = PipelineConfig(textures=False)


def _rig(name):
    return replace(rigfile.load(name), width=W, height=H, _cache={})  # an ideal rig at the frames' size


@pytest.fixture()
def shipped(tmp_path, monkeypatch):
    """A weights folder with a quad network (no recipe: the quad's, as v3's predecessors) and a one-layer
    network whose recipe says it was trained for the lag (1, 0); the pipeline's search looks only there."""
    torch.manual_seed(0)
    quad = tmp_path / "quad.pt"
    torch.save(TPNet().state_dict(), quad)
    bino = tmp_path / "tpnet_binocular_test.pt"
    torch.save(TPNet(layers=1).state_dict(), bino)
    bino.with_suffix(".json").write_text(json.dumps({"lags": [[1.0, 0.0]]}))
    monkeypatch.setattr(infer, "WEIGHTS_DIR", tmp_path)
    monkeypatch.setattr(infer, "DEFAULT_WEIGHTS", quad)
    return {"quad": quad, "binocular": bino}


def _frames(rig):
    scene = Scene([plane(rig, float(rig.distance(D)), tx.noise_texture(np.random.default_rng(0), 256, contrast=0.3))],
                  Sky())
    rendered = render(scene, rig, seed=1, supersample=1)
    return torch.from_numpy(rendered.raws.astype(np.float32) - rendered.sensor.black_level)


def test_binocular_pipeline_picks_the_binocular_weights(shipped):
    rig = _rig("binocular")
    pipe = Pipeline(H, W, rig=rig, device="cpu", max_disparity=8.0, config=NO_TEXTURES)
    assert pipe.weights == shipped["binocular"] and pipe.model.layers == 1 and pipe.layers.lags == ((1.0, 0.0),)
    result = pipe.process(_frames(rig))
    measured = torch.isfinite(result.initial)
    assert result.disparity.shape == (8, 12) and bool(measured.any())
    assert not torch.equal(result.disparity[measured], result.initial[measured])  # the network moved them
    quad = Pipeline(H, W, device="cpu", max_disparity=8.0, config=NO_TEXTURES)
    assert quad.weights == shipped["quad"] and quad.model.layers == 4


def test_mismatching_weights_are_refused(shipped):
    with pytest.raises(ValueError, match=r"weights: .*quad.pt were trained for a rig whose layers have lags "
                                         r"\[\[1.0, 0.0\], \[0.0, 1.0\], \[1.0, 1.0\], \[1.0, -1.0\]\]; this "
                                         r"pipeline's rig has \[\[1.0, 0.0\]\]"):
        Pipeline(H, W, rig=_rig("binocular"), weights=shipped["quad"], device="cpu", config=NO_TEXTURES)
    with pytest.raises(ValueError, match=r"weights: .* lags \[\[1.0, 0.0\]\]; this pipeline's rig has \[\[1.0, 0.0\], "
                                         r"\[0.0, 1.0\]"):
        Pipeline(H, W, weights=shipped["binocular"], device="cpu", config=NO_TEXTURES)


def test_mono_frames_do_not_take_colour_trained_weights(shipped, caplog):
    """The shipped weights were trained on colour (Bayer, green-only) correlations: a mono pipeline (ordinary
    images, ``tpnet process LEFT RIGHT``) runs the engine alone, and refuses such weights passed to it."""
    (shipped["binocular"].with_suffix(".json")).write_text(json.dumps(
        {"lags": [[1.0, 0.0]], "dataset_spec": {"colour_weights": [0.0, 0.0, 1.0], "fat_zero": 1e4}}))
    with caplog.at_level(logging.WARNING, logger="tpnet_gpu.pipeline"):
        pipe = Pipeline(H, W, cfa=None, rig=_rig("binocular"), device="cpu", max_disparity=8.0, config=NO_TEXTURES)
    assert pipe.weights is None and "1-colour frames" in caplog.text
    with pytest.raises(ValueError, match=r"weights: .* were trained on frames of 3 colours; these frames have 1"):
        Pipeline(H, W, cfa=None, rig=_rig("binocular"), weights=shipped["binocular"], device="cpu",
                 config=NO_TEXTURES)
    assert Pipeline(H, W, rig=_rig("binocular"), device="cpu", config=NO_TEXTURES).weights == shipped["binocular"]


def test_weights_shipped_on_request_run_only_when_asked(shipped, caplog):
    """Mono weights whose recipe says ``on_request`` (why they are not the default): ``method="auto"`` runs the
    engine alone and logs that reason; ``method="tpnet"`` takes them; "tpnet" where no weights fit at all is
    refused naming the field; colour frames still take their own weights by default."""
    shipped["binocular"].with_suffix(".json").write_text(json.dumps(
        {"lags": [[1.0, 0.0]], "dataset_spec": {"colour_weights": [0.0, 0.0, 1.0], "fat_zero": 1e4}}))
    mono = shipped["binocular"].with_name("tpnet_binocular_mono_test.pt")
    torch.save(TPNet(layers=1).state_dict(), mono)
    mono.with_suffix(".json").write_text(json.dumps({"lags": [[1.0, 0.0]], "dataset_spec": {"colour_weights": [1.0]},
                                                     "on_request": "not better on real pairs (measured)"}))
    bino = _rig("binocular")
    with caplog.at_level(logging.WARNING, logger="tpnet_gpu.pipeline"):
        auto = Pipeline(H, W, cfa=None, rig=bino, device="cpu", max_disparity=8.0, config=NO_TEXTURES)
    assert auto.weights is None and "on request only" in caplog.text and "not better on real pairs" in caplog.text
    asked = Pipeline(H, W, cfa=None, rig=bino, device="cpu", max_disparity=8.0,
                     config=replace(NO_TEXTURES, method="tpnet"))
    assert asked.weights == mono and asked.model is not None
    assert Pipeline(H, W, rig=bino, device="cpu", config=NO_TEXTURES).weights == shipped["binocular"]
    with pytest.raises(ValueError, match=r"method: 'tpnet' asks for the network, but no shipped weights fit"):
        Pipeline(H, W, rig=_rig("two_quads"), device="cpu", config=replace(NO_TEXTURES, method="tpnet"))


def test_the_shipped_quad_mono_weights_are_the_default_for_mono_quad_frames():
    """Mono frames of the quad take the quad's mono weights by default; Bayer frames keep the default weights."""
    found = infer.shipped_for(infer.lags(), 1)
    assert found is not None and found.name == "tpnet_quad_mono_v1.pt" and infer.on_request(found) is None
    assert infer.correlation(found).colour_weights == (1.0,) and infer.load(found).layers == 4
    assert infer.shipped_for(infer.lags(), 3) == infer.DEFAULT_WEIGHTS


def test_the_shipped_mono_pair_weights_run_on_request():
    """The shipped mono binocular weights are found only when asked for, and their recipe says why."""
    assert infer.shipped_for(((1.0, 0.0),), 1) is None
    found = infer.shipped_for(((1.0, 0.0),), 1, requested=True)
    assert found is not None and found.name == "tpnet_binocular_mono_v1.pt" and "real" in infer.on_request(found)
    assert infer.correlation(found).colour_weights == (1.0,) and infer.load(found).layers == 1


def test_a_rig_without_weights_runs_the_engine_alone(shipped, caplog):
    rig = _rig("two_quads")
    with caplog.at_level(logging.WARNING, logger="tpnet_gpu.pipeline"):
        pipe = Pipeline(H, W, rig=rig, device="cpu", max_disparity=8.0, config=NO_TEXTURES)
    assert pipe.weights is None and pipe.model is None and pipe.layers.count == 10
    assert "no shipped TPNET weights for this rig" in caplog.text and "the disparity is the engine's" in caplog.text
    result = pipe.process(_frames(rig))
    torch.testing.assert_close(result.disparity, result.initial, equal_nan=True, rtol=0, atol=0)


def test_every_shipped_weights_file_is_one_the_pipeline_loads():
    """The wheel carries only weights the pipeline picks for some rig and frames (by default or on request):
    each ``*.pt`` is the first match for its own lags and colour count; its recipe (JSON) keeps the history."""
    files = sorted(infer.WEIGHTS_DIR.glob("*.pt"))
    assert infer.DEFAULT_WEIGHTS in files and len(files) >= 3
    for path in files:
        colours = len(infer.correlation(path).colour_weights or (0, 0, 1))
        picked = {infer.shipped_for(infer.lags(path), colours, requested=asked) for asked in (False, True)}
        assert path in picked, (path.name, picked)
        assert path.with_suffix(".json").is_file(), path.name


def test_the_shipped_binocular_weights_are_found():
    found = infer.shipped_for(((1.0, 0.0),))
    assert found is not None and found.name == "tpnet_binocular_v1.pt"
    assert infer.load(found).layers == 1 and infer.recipe(found)["rig"]["offsets"] == [[-0.5, 0.0], [0.5, 0.0]]
    assert infer.shipped_for(infer.lags()) == infer.DEFAULT_WEIGHTS


@pytest.mark.slow
@pytest.mark.parametrize("name, max_gross, max_rmse", [
    ("binocular", 0.03, 0.09),  # measured 0.7 %, 0.069 px (the engine alone: 0.105 px)
    ("misaligned", 0.05, 0.08),  # 2.3 %, 0.044 px (the engine alone: 0.102 px)
    ("eight", 0.05, 0.11),  # 2.3 %, 0.081 px (no weights: the engine's)
])
def test_the_pipeline_measures_rendered_rigs(name, max_gross, max_rmse):
    """The whole pipeline (with the shipped weights for its rig where there are some: binocular, quad) on the
    demo scene rendered by a 2-camera rig, a quad with distortion and a known misalignment (given to the
    pipeline as its calibration), and an 8-camera rig. Oracle: the renderer's ground truth of the flat tiles."""
    rig = MISALIGNED if name == "misaligned" else RIGS[name]
    rendered = rendered_scene(rig)
    pipe = Pipeline(rig.height, rig.width, rig=rig, device="cpu", config=NO_TEXTURES)
    assert (pipe.model is None) == (name == "eight")
    result = pipe.process(rendered.raws.astype(np.float32) - rendered.sensor.black_level)
    stats = flat_stats(rendered, result.disparity)
    assert stats["tiles"] > 300 and stats["coverage"] >= 0.95
    assert stats["gross"] <= max_gross and stats["rmse_inliers"] <= max_rmse, stats


def test_method_engine_runs_the_engine_alone():
    """``PipelineConfig(method="engine")`` (``tpnet process --method engine``): no weights even where shipped ones
    fit the rig (the quad's), and weights given with it, or an unknown method, are refused naming the field."""
    from tpnet_gpu.pipeline import Pipeline, PipelineConfig  # noqa: PLC0415

    on = Pipeline(48, 64, cfa="GRBG", backend="warp", config=PipelineConfig(textures=False))
    off = Pipeline(48, 64, cfa="GRBG", backend="warp", config=PipelineConfig(textures=False, method="engine"))
    assert on.weights == infer.DEFAULT_WEIGHTS and off.weights is None and off.model is None
    with pytest.raises(ValueError, match="weights"):
        Pipeline(48, 64, cfa="GRBG", backend="warp", weights=infer.DEFAULT_WEIGHTS,
                 config=PipelineConfig(textures=False, method="engine"))
    with pytest.raises(ValueError, match=r"method: expected one of auto, tpnet, engine, got 'no'"):
        PipelineConfig(method="no")
