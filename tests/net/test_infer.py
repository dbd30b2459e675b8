"""Inference on the tile processor's output (net/infer.py): zero-copy on the same device, and the shipped
weights load and run on the CPU. Oracles: Warp's buffer pointer, and the model's own cluster form."""

import numpy as np
import pytest
import torch

from tpnet_gpu.net import infer
from tpnet_gpu.net.model import TPNet
from tpnet_gpu.processor import TileProcessor

H, W = 48, 64


def test_processor_layers_reach_the_network_without_a_copy(device, monkeypatch):
    tp = TileProcessor(H, W, device=device)
    frames = torch.from_numpy(np.random.default_rng(0).uniform(0, 1000, (4, H, W)).astype(np.float32))
    out = tp.process(frames.to(tp.torch_device), 1.0)
    assert out.layers.data_ptr() == tp._buffers.layers.ptr and out.layers.device == tp.torch_device
    model = TPNet().to(tp.torch_device)
    target = torch.full((H // 8, W // 8), 1.0, device=tp.torch_device)

    def no_host(*args, **kwargs):
        raise AssertionError("host copy in the inference path")

    monkeypatch.setattr(torch.Tensor, "cpu", no_host)
    monkeypatch.setattr(torch.Tensor, "numpy", no_host)
    monkeypatch.setattr(torch.Tensor, "item", no_host)
    disparity = infer.infer(model, out.layers, target, grid=(H // 8, W // 8))
    monkeypatch.undo()
    assert disparity.shape == (H // 8, W // 8) and disparity.device == tp.torch_device
    # the same as the cluster form at an interior tile (oracle: the model's other form)
    x = torch.cat([out.layers.reshape(H // 8, W // 8, 324), target[..., None]], dim=-1)
    ty, tx = 3, 4
    idx = [(min(max(ty + dy, 0), H // 8 - 1), min(max(tx + dx, 0), W // 8 - 1)) for dy in range(-2, 3) for dx in range(-2, 3)]
    cluster = torch.stack([x[y, x_] for y, x_ in idx])[None]
    with torch.no_grad():
        expected = target[ty, tx] + model.forward_clusters(cluster)[0, 0]
    torch.testing.assert_close(disparity[ty, tx], expected, rtol=1e-5, atol=1e-5)


def test_shipped_weights_load_and_infer_on_cpu():
    if not infer.DEFAULT_WEIGHTS.exists():
        pytest.fail(f"shipped weights missing: {infer.DEFAULT_WEIGHTS}")
    model = infer.load()
    layers = torch.zeros((6, 8, 4, 9, 9))
    out = infer.infer(model, layers, torch.full((6, 8), 2.0))
    assert out.shape == (6, 8) and torch.isfinite(out).all()
    assert "config" in infer.recipe()


def test_missing_weights_and_bad_grid(tmp_path):
    with pytest.raises(FileNotFoundError, match="no TPNET weights there"):
        infer.load(tmp_path / "none.pt")
    with pytest.raises(ValueError, match="grid: expected"):
        infer.infer(TPNet(), torch.zeros((48, 4, 9, 9)), torch.zeros((6, 8)))


def test_correlation_settings_follow_the_recipe(tmp_path):
    # the layers must be made as the weights' data set made them (oracle: the recipe's own numbers)
    import json

    from tpnet_gpu.training.dataset import DatasetSpec

    weights = tmp_path / "w.pt"
    assert infer.correlation(weights) == DatasetSpec().correlation()  # no recipe: today's data set
    weights.with_suffix(".json").write_text(json.dumps({"dataset_spec": {"fat_zero": 30.0}}))
    old = infer.correlation(weights)  # data set version 1: no colour weights = the processor's default mix
    assert old.colour_weights is None and old.fat_zero == 30.0
    weights.with_suffix(".json").write_text(json.dumps({"dataset_spec": {"fat_zero": 5.0, "colour_weights": [0, 1, 0]}}))
    assert infer.correlation(weights).colour_weights == (0, 1, 0)
    # the shipped weights come from today's data set: green-only layers, as the baseline correlates
    assert infer.correlation() == DatasetSpec().correlation()
    assert infer.correlation().colour_weights == (0.0, 0.0, 1.0)
