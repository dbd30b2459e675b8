"""Training loop (net/train.py) on a tiny rendered data set: the loss falls, runs are deterministic for a
seed, and a resumed run equals an unbroken one (oracle: the same run's own weights, bit for bit)."""

import json

import numpy as np
import pytest
import torch

from tpnet_gpu.training import dataset
from tpnet_gpu.training.dataset import DatasetSpec
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


@pytest.mark.parametrize("pass_every,stop", [(None, 2), (2, 1)])  # (2, 1): resumed between two refreshes
def test_resume_equals_an_unbroken_run(data, tmp_path, pass_every, stop):
    config = TrainConfig(epochs=4, batch=2, pass_every=pass_every)
    train(data, tmp_path / "full.pt", config, progress=False)
    train(data, tmp_path / "half.pt", config, checkpoint=tmp_path / "ck.pt", progress=False, stop_after=stop)
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


class _ZeroResidual:
    """Stands in for TPNet: predicts the target (residual 0 for every clone)."""

    def forward_frame(self, layers, target, clone=0):
        return torch.zeros(target.shape + (3,))


@pytest.mark.parametrize("error_scale", [None, 0.3])
def test_error_scale_hand_case(error_scale):
    # Oracle: hand arithmetic. 4x4 tiles, the 2x2 interior counts (the border is left out); strength 1 and
    # targets >= 8 px make the confidence and range weights equal, so the loss is the mean squared scaled error.
    from tpnet_gpu.net.train import sample_loss

    gt = torch.full((4, 4), 10.0)
    offsets = torch.tensor([[0.0, 0.1], [0.5, -1.5]])
    target = gt.clone()
    target[1:3, 1:3] += offsets
    sample = {"layers": torch.zeros(4, 4, 4, 9, 9), "target": target, "gt": gt, "strength": torch.ones(4, 4),
              "hard": torch.zeros(4, 4, dtype=torch.bool)}
    config = TrainConfig(error_scale=error_scale, mirror_lambda=0.0)
    loss = float(sample_loss(_ZeroResidual(), sample, config))
    errors = offsets.flatten().double()
    if error_scale is not None:  # 0 -> 0, 0.1 -> 0.1*0.75, 0.5 -> 0.5*0.375, -1.5 -> -1.5*0.1667
        errors = errors * error_scale / (errors.abs() + error_scale)
    assert loss == pytest.approx(float(torch.mean(errors**2)), rel=1e-5)


def test_fine_tuning_starts_from_the_given_weights(data, tmp_path):
    """A run with ``init`` and no epochs writes the init weights back bit for bit (oracle: the file it started
    from); its recipe names them and carries their recipe; the schedule is entered at ``lr_from``."""
    train(data, tmp_path / "base.pt", TrainConfig(epochs=2, batch=2), progress=False, log=lambda m: None)
    config = TrainConfig(epochs=3, batch=2, init=str(tmp_path / "base.pt"), lr_from=0.3)
    train(data, tmp_path / "tuned.pt", config, progress=False, stop_after=0, log=lambda m: None)
    base, tuned = torch.load(tmp_path / "base.pt"), torch.load(tmp_path / "tuned.pt")
    for key in base:
        torch.testing.assert_close(tuned[key], base[key], rtol=0, atol=0)
    import json

    recipe = json.loads((tmp_path / "tuned.json").read_text())
    assert "--init" in recipe["command"] and recipe["init_recipe"]["config"]["epochs"] == 2
    history = train(data, tmp_path / "t2.pt", config, progress=False, log=lambda m: None)["history"]
    assert [h["lr"] for h in history] == [3e-5, 3e-5, 1e-5]  # fractions 0.3, 0.53, 0.77 of LR_STEPS
    with pytest.raises(FileNotFoundError, match="init"):
        train(data, tmp_path / "x.pt", TrainConfig(epochs=1, init=str(tmp_path / "none.pt")), progress=False)
    with pytest.raises(ValueError, match="lr_from"):
        TrainConfig(lr_from=1.0)


def test_pass_samples_are_re_measured_at_the_models_output(data):
    """With a network that predicts no residual, the "pass" sample sits at the heuristic targets, so its
    re-measured layers must equal the heuristic layers the builder stored (oracle: the data set); a second
    refresh replaces the samples instead of adding more."""
    from tpnet_gpu.net.model import TPNet
    from tpnet_gpu.net.train import frame_samples, refresh_passes

    chunks = dataset.load(data, "train")
    samples = frame_samples(chunks, ("heuristic", "random"))
    model = TPNet()
    torch.nn.init.zeros_(model.stage2[-1].weight)  # residual = bias = 0
    measurers = dataset.measurers(SPEC, "cpu")
    measure = lambda chunk, t: dataset.remeasure(chunk, t, *measurers)  # noqa: E731
    targets = refresh_passes(model, samples, chunks, measure)
    refresh_passes(model, samples, chunks, measure)
    passes = [s for s in samples if s["variant"] == "pass"]
    assert len(passes) == len(chunks) == len(targets)
    for chunk, sample, target in zip(chunks, passes, targets):
        np.testing.assert_array_equal(target, chunk["target_heuristic"])
        expected = np.nan_to_num(chunk["layers_heuristic"].astype(np.float32))
        np.testing.assert_array_equal(sample["layers"].numpy(), expected)
    with pytest.raises(ValueError, match="pass_every"):
        TrainConfig(pass_every=0)


def test_a_binocular_data_set_trains_a_one_layer_network(tmp_path):
    """The network has one layer per direction group of the data set's rig (binocular: 1); the recipe records
    the rig and its lags; ``rig`` must be the data set's (oracle: the lags of the shipped rig files)."""
    from tpnet_gpu.io import rigfile  # noqa: PLC0415

    spec = DatasetSpec(scenes=2, width=64, height=48, test_fraction=0.5, seed=9, supersample=1,
                       rig=rigfile.rig_to_dict(rigfile.load("binocular")))
    dataset.build(tmp_path / "data", spec, device="cpu", progress=False)
    config = TrainConfig(epochs=1, batch=2)
    train(tmp_path / "data", tmp_path / "w.pt", config, progress=False, rig=rigfile.load("binocular"))
    weights = torch.load(tmp_path / "w.pt")
    assert weights["stage1.0.weight"].shape == (256, 82)
    recipe = json.loads((tmp_path / "w.json").read_text())
    assert recipe["lags"] == [[1.0, 0.0]] and recipe["rig"]["offsets"] == [[-0.5, 0.0], [0.5, 0.0]]
    assert "--rig binocular" in recipe["command"]
    with pytest.raises(ValueError, match=r"rig: the data set .* was rendered with a rig of layer lags \[\[1.0, 0.0\]\]; "
                                         r"the given rig's are \[\[1.0, 0.0\], \[0.0, 1.0\], \[1.0, 1.0\], \[1.0, -1.0\]\]"):
        train(tmp_path / "data", tmp_path / "x.pt", config, progress=False, rig=rigfile.load("quad"))
