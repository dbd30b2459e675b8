"""Taichi initialisation shared by every entry point: quiet start, a stable offline cache, arch and CPU threads.

Taichi has one runtime per process, set up by ``ti.init``: its arch (cpu or cuda) and its CPU thread count are
fixed until the next ``ti.init``. The Taichi kernels of the tile processor only take external torch tensors
(``ti.types.ndarray()``), so re-initialising for another arch loses nothing but compiled kernels, which the
offline cache reloads in milliseconds; ``use_arch`` does that when processors of both archs share a process.

* Offline cache: ``$TPNET_CACHE_DIR/taichi``, else ``~/.cache/tpnet-gpu/taichi`` (CI keeps it between runs).
* CPU threads: the ``threads`` argument of the first ``init_taichi``, else ``$TPNET_TAICHI_THREADS``, else every
  core (``os.cpu_count()``).
* ``TPNET_TAICHI_DEBUG=1``: Taichi's debug mode (bounds checks on every array access; slow; for tests).
"""

from __future__ import annotations

import contextlib
import io
import os
import threading
import warnings
from pathlib import Path

THREADS_ENV = "TPNET_TAICHI_THREADS"
DEBUG_ENV = "TPNET_TAICHI_DEBUG"
ARCHS = ("cpu", "cuda")

# Before the first `import taichi`: no version banner on stdout, no weekly version check over the network.
os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "0")
os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

with warnings.catch_warnings():  # Taichi 1.7 calls the deprecated locale.getdefaultlocale on import
    warnings.simplefilter("ignore", DeprecationWarning)
    import taichi as ti  # noqa: E402

_lock = threading.RLock()
_state: dict = {"arch": None, "threads": None}


def cache_dir() -> Path:
    """Folder of Taichi's offline kernel cache: ``$TPNET_CACHE_DIR/taichi`` or ``~/.cache/tpnet-gpu/taichi``."""
    root = os.environ.get("TPNET_CACHE_DIR") or str(Path.home() / ".cache" / "tpnet-gpu")
    return Path(root) / "taichi"


def _threads_from_env() -> int:
    raw = os.environ.get(THREADS_ENV)
    if not raw:
        return os.cpu_count() or 1
    try:
        threads = int(raw)
    except ValueError:
        threads = 0
    if threads < 1:
        raise ValueError(f"{THREADS_ENV}: expected a positive number of threads, got {raw!r}")
    return threads


def init_taichi(arch: str = "cpu", threads: int | None = None) -> None:
    """Initialise Taichi for ``arch`` ("cpu" or "cuda") once per process (again only when the arch changes).

    ``threads`` sets the CPU thread pool at the first initialisation; asking for another count later raises
    (Taichi fixes it at ``ti.init``: run each thread count in its own process).
    """
    if arch not in ARCHS:
        raise ValueError(f"arch: expected one of {ARCHS}, got {arch!r}")
    if threads is not None and (not isinstance(threads, int) or threads < 1):
        raise ValueError(f"threads: expected a positive number of threads, got {threads!r}")
    with _lock:
        if _state["threads"] is not None and threads is not None and threads != _state["threads"]:
            raise ValueError(
                f"threads: Taichi already runs {_state['threads']} CPU threads in this process, got {threads} "
                "(the count is fixed at the first initialisation)"
            )
        if _state["arch"] == arch:
            return
        count = _state["threads"] or threads or _threads_from_env()
        cache = cache_dir()
        cache.mkdir(parents=True, exist_ok=True)
        with contextlib.redirect_stdout(io.StringIO()):  # ti.init prints "[Taichi] Starting on arch=..."
            ti.init(
                arch=ti.cuda if arch == "cuda" else ti.cpu,
                enable_fallback=False,  # no silent CPU run when CUDA was asked for
                cpu_max_num_threads=count,
                offline_cache=True,
                offline_cache_file_path=str(cache),
                log_level=ti.WARN,
                default_fp=ti.f32,
                default_ip=ti.i32,
                debug=os.environ.get(DEBUG_ENV, "0") not in ("", "0"),
            )
        _touch()  # materialises the runtime on this thread: Taichi aborts when a worker thread does it first
        _state.update(arch=arch, threads=count)


@ti.kernel
def _touch():
    pass


def use_arch(arch: str) -> None:
    """Make ``arch`` Taichi's current arch before a launch (re-initialises only when it changes)."""
    if _state["arch"] != arch:
        init_taichi(arch)


def threads() -> int | None:
    """Taichi's CPU thread count in this process (None before the first initialisation)."""
    return _state["threads"]


def current_arch() -> str | None:
    """"cpu" or "cuda" after an initialisation, else None."""
    return _state["arch"]
