"""The benchmark's plain-PyTorch peer (tpnet_gpu.bench.twins.torch_tp, bench/twins/torch_tp.py) against the golden
float64 reference (CPU tensors).

Oracle: tpnet_gpu.reference (bayer_planes + convert_tiles per camera, correlate per pair), through the helpers of
tests/bench/twins/test_numpy_tp.py (same random cases: windows partly and wholly off the image, round-half corners).
Tolerance: max |torch - reference| <= 1e-4 x max |reference| (the peer is float32 throughout).
"""

import numpy as np
import pytest
import torch

from tests.bench.twins.test_numpy_tp import (
    CAMS, CORRELATE_CASES, TOL, imported_names, random_case, reference_clt, relative_error)
from tpnet_gpu import reference as ref
from tpnet_gpu import tables
from tpnet_gpu.bench.twins import torch_tp


@pytest.fixture(autouse=True)
def one_torch_thread():
    """Tiny tensors: intra-op threads only add overhead, and on a loaded machine OpenMP's barriers make these
    40-tile cases take seconds instead of milliseconds. Restored afterwards."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.mark.parametrize("cfa", ["GRBG", "RGGB", None])
@pytest.mark.parametrize("chunk", [None, 7])  # 7: chunk boundaries inside the 40 tiles
def test_convert_equals_reference(cfa, chunk):
    frames, centres = random_case(1)
    got = torch_tp.torch_convert(torch.from_numpy(frames), torch.from_numpy(centres), cfa, chunk=chunk)
    want = reference_clt(frames, centres, cfa)
    assert isinstance(got, torch.Tensor) and got.dtype == torch.float32 and got.device.type == "cpu"
    assert tuple(got.shape) == (40, CAMS, 1 if cfa is None else 3, 4, 8, 8)
    assert relative_error(got.numpy(), want) <= TOL


def test_convert_accepts_arrays_and_integer_frames():
    frames, centres = random_case(5)
    frames = np.round(frames).astype(np.uint16)
    got = torch_tp.torch_convert(frames, centres, "GRBG")
    assert relative_error(got.numpy(), reference_clt(frames.astype(np.float32), centres, "GRBG")) <= TOL


@pytest.mark.parametrize("cfa, pairs, inside, kwargs", CORRELATE_CASES)
@pytest.mark.parametrize("chunk", [None, 9])
def test_correlate_equals_reference(cfa, pairs, inside, kwargs, chunk):
    # Input: the reference CLT rounded to float32, so this checks the correlate stage alone.
    frames, centres = random_case(2, inside=inside)
    clt = reference_clt(frames, centres, cfa)
    got = torch_tp.torch_correlate(torch.from_numpy(clt.astype(np.float32)), pairs, **kwargs, chunk=chunk)
    want = np.stack([ref.correlate(clt[:, a], clt[:, b], **kwargs) for a, b in pairs], axis=1)
    assert got.dtype == torch.float32
    assert tuple(got.shape) == (40, len(pairs), 15, 15)
    assert relative_error(got.numpy(), want) <= TOL


def test_correlate_zero_tiles_without_fat_zero_are_zero():
    clt = torch.zeros((2, 2, 3, 4, 8, 8))
    clt[1] = torch.from_numpy(np.random.default_rng(3).standard_normal((2, 3, 4, 8, 8)).astype(np.float32))
    corr = torch_tp.torch_correlate(clt, [(0, 1)], (0.25, 0.25, 0.5), 0.0, 0.5, 0.9)
    assert torch.all(corr[0] == 0.0)
    assert torch.all(torch.isfinite(corr)) and corr[1].abs().max() > 0


@pytest.mark.parametrize("cfa", ["GRBG", None])
def test_full_pipeline_defaults_equal_reference(cfa):
    # torch_convert -> torch_correlate with the defaults (GPU-path constants) vs the reference chain.
    frames, centres = random_case(4, inside=True)
    got = torch_tp.torch_correlate(torch_tp.torch_convert(torch.from_numpy(frames), torch.from_numpy(centres), cfa))
    clt = reference_clt(frames, centres, cfa)
    want = np.stack([ref.correlate(clt[:, a], clt[:, b]) for a, b in tables.QUAD_PAIRS], axis=1)
    assert relative_error(got.numpy(), want) <= TOL


def test_peer_does_not_import_the_reference():
    names = imported_names(torch_tp)  # (its shared twins.common: checked in test_numpy_tp)
    assert not [m for m in names if m.startswith("tpnet_gpu.reference")], names


@pytest.mark.parametrize("offset", [tables.NET_CORR_OFFSET, -1.0])
def test_layers_equal_reference(offset):
    corr = np.random.default_rng(6).standard_normal((30, 6, 15, 15)).astype(np.float32)
    got = torch_tp.torch_layers(torch.from_numpy(corr), offset)
    want = ref.network_layers(corr.astype(np.float64), offset=offset)
    assert tuple(got.shape) == (30, 4, 9, 9)
    assert relative_error(got.numpy(), want) <= TOL


def test_equals_the_processor_on_its_device(device):
    # Oracle: the Warp processor (itself checked against the reference in tests/kernels); the twin runs on the
    # processor's torch device, reads its tile centres and keeps its outputs there.
    from tpnet_gpu.processor import TileProcessor

    frames, _ = random_case(7)
    tp = TileProcessor(frames.shape[1], frames.shape[2], clt=True, device=device)
    out = tp.process(frames, 1.5)
    frames_t = torch.from_numpy(frames).to(tp.torch_device)
    clt = torch_tp.torch_convert(frames_t, out.centres, "GRBG")
    corr = torch_tp.torch_correlate(clt)
    layers = torch_tp.torch_layers(corr)
    assert clt.device == corr.device == layers.device == tp.torch_device
    for got, want in ((clt, out.clt), (corr, out.corr), (layers, out.layers)):
        assert relative_error(got.cpu().numpy(), want.cpu().numpy().astype(np.float64)) <= TOL
