"""Frames that follow the one before (``disparity.follow``, ``Pipeline.stream(follow=True)``). Oracle: the
renderer's exact ground truth - a followed frame must be as right as a searched one, and tiles whose previous
answer is made wrong by 20 px (a surface that jumped) must be found again by the sweep of the lost tiles - and
the count of tile passes the engine reports."""

import numpy as np
import pytest

from tpnet_gpu import evaluation
from tpnet_gpu.camera import Rig
from tpnet_gpu.config import PipelineConfig
from tpnet_gpu.disparity import DisparityEngine
from tpnet_gpu.disparity.follow import REFRESH
from tpnet_gpu.disparity.results import DisparityResult
from tpnet_gpu.pipeline import FrameError, Pipeline
from tpnet_gpu.scenes import Sensor, demo_scene, render

RIG = Rig(width=256, height=192)


@pytest.fixture(scope="module")
def frame():
    rendered = render(demo_scene(RIG, seed=3), RIG, sensor=Sensor(), supersample=1, seed=3)
    return rendered.raws.astype(np.float32) - rendered.sensor.black_level, rendered


def _gross(result, rendered) -> float:
    classes = evaluation.tile_classes(rendered.tile_disparity, rendered.tile_confidence, rendered.tile_spread)
    d = result.disparity.cpu().numpy().astype(np.float64)
    return evaluation.error_stats(d, rendered.tile_disparity, classes["all"])["gross"]


def test_a_followed_frame_is_as_right_as_a_searched_one_in_fewer_passes(frame):
    frames, rendered = frame
    engine = DisparityEngine(RIG.height, RIG.width, rig=RIG, device="cpu")
    searched = engine.run(frames)
    kept = DisparityResult(*(t.clone() if hasattr(t, "clone") else t for t in (
        searched.disparity, searched.strength, searched.confidence, searched.two_depth, searched.search,
        searched.margin, searched.tile_passes)))
    followed = engine.run(frames, previous=kept)
    assert 1.0 <= followed.tile_passes < 0.6 * searched.tile_passes
    assert _gross(followed, rendered) <= _gross(searched, rendered) + 0.005


def test_tiles_whose_answer_jumped_are_searched_again(frame):
    frames, rendered = frame
    engine = DisparityEngine(RIG.height, RIG.width, rig=RIG, device="cpu")
    searched = engine.run(frames)
    wrong = searched.disparity.clone()
    block = (slice(8, 16), slice(10, 22))
    wrong[block] = wrong[block] + 20.0  # a surface that jumped: a pass at the old answer reads no peak
    previous = DisparityResult(wrong, searched.strength.clone(), searched.confidence.clone(),
                               searched.two_depth.clone(), wrong.clone(), searched.margin.clone(),
                               searched.tile_passes)
    followed = engine.run(frames, previous=previous)
    gt = rendered.tile_disparity[block]
    d = np.nan_to_num(followed.disparity.cpu().numpy()[block], nan=1e9)  # no answer counts wrong
    # found again: 98 % of the block's tiles within 1 px (without the lost tiles' sweep: 76 %, the rest left
    # 20 px off or unanswered, measured when this test was written)
    assert np.mean(np.abs(d - gt) <= 1.0) > 0.95
    assert followed.tile_passes > 1.05  # the lost tiles' sweep ran


@pytest.mark.slow
def test_stream_follows_refreshes_and_restarts_after_a_bad_frame(frame):
    frames, _ = frame
    pipeline = Pipeline(RIG.height, RIG.width, rig=RIG, device="cpu", config=PipelineConfig(textures=False))
    items = [frames] * (REFRESH + 5)
    items[3] = frames[:2]  # a bad frame (two cameras of four): a FrameError, then a full search
    out = list(pipeline.stream(items, follow=True))
    assert isinstance(out[3], FrameError)
    passes = [r.tile_passes if not isinstance(r, FrameError) else None for r in out]
    searched = passes[0]
    assert passes[1] < 0.6 * searched and passes[2] < 0.6 * searched
    assert passes[4] == pytest.approx(searched)  # after the bad frame: searched again
    assert passes[5] < 0.6 * searched
    assert passes[4 + REFRESH - 1] < 0.6 * searched and passes[4 + REFRESH] == pytest.approx(searched)  # refresh
    plain = [r.tile_passes for r in pipeline.stream([frames] * 3)]
    assert plain == pytest.approx([searched] * 3)  # without follow every frame is searched


# --- the rig's forward motion (follow.carried, follow.measured_motion). Oracle: the renderer's ground truth of a
# scene seen before and after the rig stepped forward, and the step itself (k = t_z / (B f)).
# A VGA frame: the small RIG's demo scene has few near tiles, and an answer's 0.2 px (the followed frames' refinement
# tolerance) at its largest disparity, 14 px, is 0.001 in 1/d - a third of k
VGA, STEP_MM = Rig(width=640, height=480), 1500.0


@pytest.fixture(scope="module")
def forward():
    """Three frames of the demo scene as a rig stepping ``STEP_MM`` forward per frame sees it, with their truths."""
    from tpnet_gpu.scenes.motion import RigMotion, moved_scene  # noqa: PLC0415

    scene, out = demo_scene(VGA, seed=5), []
    for k in range(3):
        rendered = render(scene, VGA, sensor=Sensor(), supersample=1, seed=5 + k)
        out.append((rendered.raws.astype(np.float32) - rendered.sensor.black_level, rendered))
        scene = moved_scene(scene, RigMotion(translation=(0.0, 0.0, -STEP_MM)))
    return out


def _near(d, truth, tolerance=0.5) -> float:
    """Share of the tiles with ground truth of 2 px or more (near enough for the step to move them: the demo's
    sky and far hills are most of the frame) whose ``d`` is within ``tolerance`` px of it."""
    known = np.isfinite(truth) & (truth >= 2.0)
    return float(np.mean(np.abs(np.nan_to_num(d, nan=1e9)[known] - truth[known]) <= tolerance))


def test_carried_answers_meet_the_moved_rigs_truth(forward):
    from tpnet_gpu.disparity.follow import carried  # noqa: PLC0415
    import torch  # noqa: PLC0415

    before, after = forward[0][1].tile_disparity, forward[1][1].tile_disparity
    k = STEP_MM / (VGA.baseline_mm * VGA.focal_px)
    moved = carried(torch.from_numpy(before.astype(np.float32)), k).numpy()
    # measured when written: 0.38 unmoved, 0.88 carried (the rest: edges the step uncovered)
    assert _near(before, after) < 0.5  # the step matters
    assert _near(moved, after) > 0.8
    assert np.array_equal(carried(torch.from_numpy(before.astype(np.float32)), 0.0).numpy(), before.astype(
        np.float32), equal_nan=True)


@pytest.mark.slow
def test_a_stream_measures_the_rigs_forward_step_and_a_still_rig_none(forward):
    pipeline = Pipeline(VGA.height, VGA.width, rig=VGA, device="cpu", config=PipelineConfig(textures=False))
    out = list(pipeline.stream([f for f, _ in forward], follow=True))
    results = [r.engine.motion for r in out]
    assert out[2].tile_passes < 0.6 * out[0].tile_passes  # followed: a 1.5 m step per frame is no cut
    k = STEP_MM / (VGA.baseline_mm * VGA.focal_px)
    assert results[0] == 0.0  # a searched frame measures nothing
    # measured when written: 0.99 k and 1.00 k
    assert results[1] == pytest.approx(k, rel=0.1) and results[2] == pytest.approx(k, rel=0.1)
    still = [r.engine.motion for r in pipeline.stream([forward[0][0]] * 3, follow=True)]
    assert abs(still[1]) < 0.05 * k and abs(still[2]) < 0.05 * k


def test_the_kept_answers_carry_the_measured_motion(frame):
    from dataclasses import replace  # noqa: PLC0415

    from tpnet_gpu.pipeline import _kept  # noqa: PLC0415

    engine = DisparityEngine(RIG.height, RIG.width, rig=RIG, device="cpu")
    first = _kept(replace(engine.run(frame[0]), motion=0.001), None)
    second = _kept(replace(engine.run(frame[0]), motion=0.002), first)  # written into the first's copy
    assert second.disparity is first.disparity and (first.motion, second.motion) == (0.001, 0.002)


@pytest.mark.slow
def test_a_cut_is_searched_in_full_and_answered_as_a_searched_frame(frame):
    # Oracle: a fresh engine's search of the frame after the cut (its answers and passes), and the ground truth.
    from tpnet_gpu.scenes import random_scene  # noqa: PLC0415

    other = render(random_scene(RIG, np.random.default_rng([500, 1])), RIG, sensor=Sensor(), supersample=1, seed=9)
    cut = other.raws.astype(np.float32) - other.sensor.black_level
    pipeline = Pipeline(RIG.height, RIG.width, rig=RIG, device="cpu", config=PipelineConfig(textures=False))
    results = list(pipeline.stream([frame[0], frame[0], cut], follow=True))
    searched = DisparityEngine(RIG.height, RIG.width, rig=RIG, device="cpu").run(cut)
    assert results[1].tile_passes < 0.6 * results[0].tile_passes  # the same view: followed
    assert results[2].tile_passes == pytest.approx(searched.tile_passes)
    assert np.array_equal(results[2].engine.disparity.numpy(), searched.disparity.numpy(), equal_nan=True)


def test_masked_pixels_do_not_make_a_cut(frame):
    # A block of NaN pixels (a documented masked input) in every frame: the frames still follow each other (the
    # views compared where both are finite); oracle: the passes of a searched frame.
    frames = frame[0].copy()
    frames[:, 40:80, 60:120] = np.nan
    pipeline = Pipeline(RIG.height, RIG.width, rig=RIG, device="cpu", config=PipelineConfig(textures=False))
    out = list(pipeline.stream([frames, frames], follow=True))
    assert out[1].tile_passes < 0.6 * out[0].tile_passes
