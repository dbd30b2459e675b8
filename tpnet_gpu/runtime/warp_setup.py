"""Warp initialisation shared by every entry point: quiet logging, a stable kernel cache, device choice."""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import os
from pathlib import Path

import warp as wp

_initialised = False
# Set (not "0") before the first kernel launch: Warp builds every kernel module in its debug mode (bounds checks
# on every array access; an out-of-range index stops the process with "Assertion failed"). Read once, in
# init_warp: Warp resolves the mode when a module is first loaded, so setting wp.config.mode after that (as the
# issue-16 campaign first tried) leaves the release builds in use. Debug builds have their own cache entries.
DEBUG_ENV = "TPNET_WARP_DEBUG"


def debug() -> bool:
    """Whether this process builds Warp kernels in debug mode (``DEBUG_ENV``)."""
    return os.environ.get(DEBUG_ENV, "0") not in ("", "0")


def init_warp() -> None:
    """Initialise Warp once. The kernel cache goes to ``$WARP_CACHE_PATH`` when set (CI keeps it stable); with
    ``$TPNET_WARP_DEBUG`` set, kernels are built in Warp's debug mode (``DEBUG_ENV``)."""
    global _initialised
    if _initialised:
        return
    if debug():
        wp.config.mode = "debug"
    wp.config.log_level = wp.LOG_WARNING
    if os.environ.get("WARP_CACHE_PATH"):
        wp.config.kernel_cache_dir = os.environ["WARP_CACHE_PATH"]
    wp.init()
    _initialised = True


def default_device() -> str:
    """"cuda" when a CUDA device is present, else "cpu"."""
    init_warp()
    return "cuda" if wp.is_cuda_available() else "cpu"


@functools.cache
def kernel_module_options() -> dict:
    """The module options of every Warp kernel module (``kernels/*.py``): no backward pass, and a digest of all
    the kernel sources. Warp 1.19's content hash leaves out the functions a kernel only passes to ``tile_map``
    (measured: changing one left the hash as it was, and a warm cache served the old code - issue 16); the
    options are hashed, so any edit of a kernel file now gives its modules, and the modules that call into it,
    a new hash."""
    digest = hashlib.sha256()
    folder = importlib.util.find_spec("tpnet_gpu.kernels").submodule_search_locations[0]  # kernels/ in the repo
    for path in sorted(Path(folder).glob("*.py")):
        digest.update(path.name.encode() + path.read_bytes())
    return {"enable_backward": False, "kernel_sources": digest.hexdigest()[:16]}
