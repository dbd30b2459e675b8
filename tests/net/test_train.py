"""Training loop (net/train.py) on a tiny rendered data set: the loss falls, runs are deterministic for a
seed, and a resumed run equals an unbroken one (oracle: the same run's own weights, bit for bit)."""

import numpy as np
import pytest
import torch

from tpnet_gpu import dataset
from tpnet_gpu.dataset import DatasetSpec
from tpnet_gpu.net.train import TrainConfig, relative_spread, train

SPEC = DatasetSpec(scenes=3, width=64, height=48, test_fraction=0.34, seed=9, supersample=1)


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    folder = tmp_path_factory.mktemp("data")
    dataset.build(folder, SPEC, device="cpu", progress=False)
    return folder



def test_loss_falls_and_runs_are_deterministic(data, tmp_path):
    config = TrainConfig(epochs=6, batch=2)
    a = train(data, tmp_path / "a.pt", config, progress=False, log=lambda m: None)["history"]
    b = train(data, tmp_path / "b.pt", config, progress=False, log=lambda m: None)["history"]
    assert a[-1]["loss"] < a[0]["loss"]
    assert [h["loss"] for h in a] == [h["loss"] for h in b]
    assert (tmp_path / "a.json").exists()


def test_resume_equals_an_unbroken_run(data, tmp_path):
    config = TrainConfig(epochs=4, batch=2)
    train(data, tmp_path / "full.pt", config, progress=False)
    train(data, tmp_path / "half.pt", config, checkpoint=tmp_path / "ck.pt", progress=False, stop_after=2)
    train(data, tmp_path / "resumed.pt", config, checkpoint=tmp_path / "ck.pt", progress=False, log=lambda m: None)
    full = torch.load(tmp_path / "full.pt")
    resumed = torch.load(tmp_path / "resumed.pt")
    for key in full:
        torch.testing.assert_close(resumed[key], full[key], rtol=0, atol=0)


def test_relative_spread_scaling():
    gt = np.zeros((6, 6))
    gt[3, 3] = 10.0  # max >= 5: spread scaled by 5 / max
    v = relative_spread(gt)
    assert v[3, 3] == pytest.approx(5.0) and v[0, 0] == 0.0
