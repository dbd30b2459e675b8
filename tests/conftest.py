"""Shared fixtures: the Warp devices to test on (CPU always; CUDA when present, else skipped with a reason) and the
kernel backends (Warp and Taichi: every parametrised test runs the same oracle comparison on both) and the tile
passes (split: convert + correlate through the kept CLT tiles; fused: one pass without them), as the
``TileProcessor`` keyword that selects them."""

import pytest


def _cuda_available() -> bool:
    import warp as wp  # on use: tests that need no kernels (docs, packaging) run without Warp

    from tpnet_gpu.runtime.warp_setup import init_warp

    init_warp()
    return wp.is_cuda_available()


@pytest.fixture(params=["cpu", "cuda"])
def device(request):
    if request.param == "cuda" and not _cuda_available():
        pytest.skip("no CUDA device on this machine")
    return request.param


@pytest.fixture(params=["warp", "taichi"])
def backend(request):
    return request.param


@pytest.fixture(params=[True, False], ids=["split", "fused"])
def keep_clt(request):
    """``clt=`` of ``TileProcessor``: True keeps the CLT tiles (split stages), False runs the fused pass."""
    return request.param
