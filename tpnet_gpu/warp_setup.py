"""Warp initialisation shared by every entry point: quiet logging, a stable kernel cache, device choice."""

from __future__ import annotations

import os

import warp as wp

_initialised = False


def init_warp() -> None:
    """Initialise Warp once. The kernel cache goes to ``$WARP_CACHE_PATH`` when set (CI keeps it stable)."""
    global _initialised
    if _initialised:
        return
    wp.config.log_level = wp.LOG_WARNING
    if os.environ.get("WARP_CACHE_PATH"):
        wp.config.kernel_cache_dir = os.environ["WARP_CACHE_PATH"]
    wp.init()
    _initialised = True


def default_device() -> str:
    """"cuda" when a CUDA device is present, else "cpu"."""
    init_warp()
    return "cuda" if wp.is_cuda_available() else "cpu"
