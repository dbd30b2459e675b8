"""ONNX export of the network (net/export.py, issue 18): the exported graph, run by onnxruntime on two frame sizes
that differ from the traced one, gives PyTorch's whole-frame prediction (``infer.infer``, the pipeline's call).
Oracle: PyTorch's own kernels on the same inputs; onnxruntime is a separate runtime with its own convolution and
matmul kernels, so the tolerance is float32 rounding of sums of ~800 products: 2e-5 px + 1e-5 relative.
Also: the file is written whole and never clobbered. Skips with a reason without onnx/onnxruntime/onnxscript."""

import numpy as np
import pytest
import torch

pytest.importorskip("onnx", reason="the onnx extra is not installed (pip install 'tpnet-gpu[onnx]')")
pytest.importorskip("onnxscript", reason="the onnx extra is not installed (pip install 'tpnet-gpu[onnx]')")
ort = pytest.importorskip("onnxruntime", reason="the onnx extra is not installed (pip install 'tpnet-gpu[onnx]')")

from tpnet_gpu.net import infer  # noqa: E402
from tpnet_gpu.net.export import export_onnx  # noqa: E402

ATOL, RTOL = 2e-5, 1e-5  # px


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    model = infer.load()  # the shipped quad weights: outputs of a trained network, not of random weights
    path = export_onnx(model, tmp_path_factory.mktemp("onnx") / "tpnet.onnx")
    return model, path


def _frame(ty: int, tx: int, seed: int):
    rng = np.random.default_rng(seed)
    layers = rng.normal(0.0, 0.3, (ty, tx, 4, 9, 9)).astype(np.float32)
    target = rng.uniform(0.0, 6.0, (ty, tx)).astype(np.float32)
    target[0, 1] = target[ty - 1, tx - 2] = np.nan  # no target there: the output stays NaN, neighbours read 0
    return layers, target


@pytest.mark.slow
@pytest.mark.parametrize("grid", [(5, 7), (13, 9)], ids=["5x7", "13x9"])
def test_onnxruntime_matches_pytorch_on_frame_sizes_it_was_not_traced_on(exported, grid):
    model, path = exported
    layers, target = _frame(*grid, seed=grid[0])
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    assert [i.name for i in session.get_inputs()] == ["layers", "target"]
    (got,) = session.run(["disparity"], {"layers": layers, "target": target})
    expected = infer.infer(model, torch.from_numpy(layers), torch.from_numpy(target)).numpy()
    assert got.shape == grid and got.dtype == np.float32
    np.testing.assert_array_equal(np.isnan(got), np.isnan(target))
    np.testing.assert_allclose(got, expected, atol=ATOL, rtol=RTOL, equal_nan=True)
    assert np.nanmax(np.abs(got - target)) > 0.01  # the residual is really there (not target + 0)


def test_export_refuses_an_existing_file_and_leaves_it_alone(tmp_path):
    path = tmp_path / "old.onnx"
    path.write_bytes(b"keep me")
    with pytest.raises(ValueError, match=r"path: expected a new file \(or --overwrite\), got .*old.onnx, which exists"):
        export_onnx(infer.load(), path)
    assert path.read_bytes() == b"keep me"
    with pytest.raises(ValueError, match=r"path: expected a file name ending in .onnx, got"):
        export_onnx(infer.load(), tmp_path / "net.pt")
    with pytest.raises(ValueError, match=r"opset: expected an int >= 18"):
        export_onnx(infer.load(), tmp_path / "new.onnx", opset=13)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.onnx"]  # nothing half-written beside it


def test_a_failed_export_leaves_no_file(tmp_path, monkeypatch):
    def fail(*args, **kwargs):
        raise RuntimeError("exporter failed")

    monkeypatch.setattr(torch.onnx, "export", fail)
    with pytest.raises(RuntimeError, match="exporter failed"):
        export_onnx(infer.load(), tmp_path / "net.onnx")
    assert list(tmp_path.iterdir()) == []
