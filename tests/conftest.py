"""Shared fixtures: the Warp devices to test on (CPU always; CUDA when present, else skipped with a reason)."""

import pytest

from tpnet_gpu.warp_setup import init_warp


def _cuda_available() -> bool:
    import warp as wp

    init_warp()
    return wp.is_cuda_available()


@pytest.fixture(params=["cpu", "cuda"])
def device(request):
    if request.param == "cuda" and not _cuda_available():
        pytest.skip("no CUDA device on this machine")
    return request.param
