"""Frame pipeline (tpnet_gpu/pipeline.py): on a rendered plane the on-device estimate finds the known
disparity, nothing goes to the host, streaming works, and memory stays flat over many frames.
Oracle: the disparity the plane was rendered at."""

import numpy as np
import pytest
import torch

from tpnet_gpu.camera import Rig
from tpnet_gpu.net.model import TPNet
from tpnet_gpu.pipeline import Pipeline, PipelineConfig
from tpnet_gpu.scenes import Scene, Sky, plane, render
from tpnet_gpu.scenes import textures as tx

RIG = Rig(width=96, height=64)
D = 3.3


@pytest.fixture(scope="module")
def weights(tmp_path_factory):
    path = tmp_path_factory.mktemp("w") / "random.pt"
    torch.manual_seed(0)
    torch.save(TPNet().state_dict(), path)  # untrained: these tests check plumbing, not accuracy
    return path


@pytest.fixture(scope="module")
def frames():
    scene = Scene([plane(RIG, float(RIG.distance(D)), tx.noise_texture(np.random.default_rng(0), 256, contrast=0.3))], Sky())
    rendered = render(scene, RIG, seed=1)
    return torch.from_numpy(rendered.raws.astype(np.float32) - rendered.sensor.black_level)


def test_pipeline_measures_the_plane_on_device(frames, weights, device, monkeypatch):
    # the default, on-device measurement ("axis"; the quad's optional LMA fit is float64 NumPy)
    pipe = Pipeline(RIG.height, RIG.width, weights=weights, device=device, max_disparity=12.0)
    on_device = frames.to(pipe.device)
    pipe.process(on_device)  # warm-up (kernels, tables)

    def no_host(*args, **kwargs):
        raise AssertionError("host round trip inside the pipeline")

    for name in ("cpu", "numpy", "item", "tolist"):
        monkeypatch.setattr(torch.Tensor, name, no_host)
    result = pipe.process(on_device)
    monkeypatch.undo()
    assert result.disparity.device == pipe.device and result.disparity.shape == (8, 12)
    assert result.texture.shape == (4, RIG.height, RIG.width)
    initial = result.initial.cpu().numpy()[1:-1, 1:-1]
    assert np.median(np.abs(initial - D)) < 0.1  # the engine's search + axis-peak refinement
    assert result.valid.cpu().numpy()[1:-1, 1:-1].all() and (result.confidence.cpu().numpy()[1:-1, 1:-1] > 0.1).all()


def test_stream_and_flat_memory(frames, weights):
    import resource

    pipe = Pipeline(RIG.height, RIG.width, weights=weights, device="cpu", max_disparity=12.0)
    list(pipe.stream([frames] * 5))  # warm up allocators and caches
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    count = sum(1 for _ in pipe.stream(frames + float(i) for i in range(40)))
    after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    assert count == 40
    assert after - before < 20_000  # KiB: no per-frame growth (buffers are allocated once)


def test_bad_network_passes():
    with pytest.raises(ValueError, match="network_passes: expected an int >= 1, got 0"):
        PipelineConfig(network_passes=0)
