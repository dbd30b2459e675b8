"""Pipeline.stream survives bad frames (issue 16: a (3, H, W) frame at frame 120 of 320 ended the generator).
Oracle: the stream of the same good frames without the bad ones (the results after a bad frame must equal those
of a stream that never saw it, bit for bit: nothing of a refused frame may leak into the next)."""

import numpy as np
import pytest
import torch

from tpnet_gpu.camera import Rig
from tpnet_gpu.net.model import TPNet
from tpnet_gpu.pipeline import FrameError, Pipeline

RIG = Rig(width=48, height=32)


@pytest.fixture(scope="module")
def weights(tmp_path_factory):
    path = tmp_path_factory.mktemp("w") / "random.pt"
    torch.manual_seed(0)
    torch.save(TPNet().state_dict(), path)  # untrained: plumbing, not accuracy
    return path


def _snapshot(result):
    return None if isinstance(result, FrameError) else (result.disparity.clone(), result.texture.clone())


def test_issue16_stream_goes_on_after_a_bad_frame(weights):
    rng = np.random.default_rng(5)
    good = [rng.uniform(0, 3000, (4, RIG.height, RIG.width)).astype(np.float32) for _ in range(3)]
    bad = [good[0][:3], "not a frame", np.zeros((4, RIG.height, RIG.width), np.complex64)]
    frames = [good[0], bad[0], good[1], bad[1], bad[2], good[2]]
    pipe = Pipeline(RIG.height, RIG.width, weights=weights, device="cpu", max_disparity=6.0, backend="warp")
    got = [_snapshot(r) if not isinstance(r, FrameError) else r for r in pipe.stream(frames)]
    assert len(got) == len(frames)
    errors = [r for r in got if isinstance(r, FrameError)]
    assert [e.index for e in errors] == [1, 3, 4]
    assert isinstance(errors[0].error, ValueError) and "frames: expected shape (4, 32, 48)" in str(errors[0].error)
    assert isinstance(errors[1].error, TypeError) and isinstance(errors[2].error, TypeError)
    fresh = Pipeline(RIG.height, RIG.width, weights=weights, device="cpu", max_disparity=6.0, backend="warp")
    want = [_snapshot(r) for r in fresh.stream(good)]
    for (disparity, texture), (want_d, want_t) in zip([g for g in got if not isinstance(g, FrameError)], want):
        torch.testing.assert_close(disparity, want_d, rtol=0, atol=0, equal_nan=True)
        torch.testing.assert_close(texture, want_t, rtol=0, atol=0)
