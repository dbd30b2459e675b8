"""Taichi initialisation shared by every entry point: quiet start, a stable offline cache, arch and CPU threads.

Taichi has one runtime per process, set up by ``ti.init``: its arch (cpu or cuda) and its CPU thread count are
fixed until the next ``ti.init``. The Taichi kernels of the tile processor only take external torch tensors
(``ti.types.ndarray()``), alone or grouped in argument packs (``ti.types.argpack``), so re-initialising for
another arch loses nothing but compiled kernels, which the offline cache reloads in milliseconds, and the packs,
which live in one runtime: ``argpacks`` makes them again (``use_arch`` re-initialises when processors of both
archs share a process).

* Offline cache: ``$TPNET_CACHE_DIR/taichi``, else ``~/.cache/tpnet-gpu/taichi`` (CI keeps it between runs).
* CPU threads: the ``threads`` argument of the first ``init_taichi``, else ``$TPNET_TAICHI_THREADS``, else every
  core (``os.cpu_count()``).
* ``TPNET_TAICHI_DEBUG=1``: Taichi's debug mode (bounds checks on every array access; slow; for tests).

Start-up (docs/platform.md §4): Taichi 1.7's offline cache keeps each kernel's compiled code keyed by its
IR, so every process still turns each kernel's Python source into IR (the front end) before it finds its cached
code. Two parts of that front end cost more than the rest together and do not change the IR, so
``quick_front_end`` (applied on import) replaces them: the source position written for every AST node (line-wrapped
with a caret hint: ~60% of the front end; the kernel's file, line and source line are kept, the format Taichi itself
uses on Python < 3.8), and the class-body test of every ``@ti.kernel`` / ``@ti.func`` decorator (it searched all
of ``sys.modules`` for the caller's source file; the line is read from ``linecache``). Debug mode keeps Taichi's
own positions (for the best bounds-check messages).
"""

from __future__ import annotations

import atexit
import contextlib
import io
import linecache
import os
import sys
import threading
import warnings
import weakref
from collections.abc import Callable
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

FRONT_END_VERSIONS = ((1, 7),)  # Taichi versions whose front-end internals quick_front_end replaces


def _debug() -> bool:
    return os.environ.get(DEBUG_ENV, "0") not in ("", "0")


def _position(ctx, node) -> str:
    """A node's source position, as Taichi's ``ASTTransformerContext.get_pos_info`` without the caret hint."""
    return (f'File "{ctx.file}", line {node.lineno + ctx.lineno_offset}, in {ctx.func.func.__name__}:\n'
            f"{ctx.src[node.lineno - 1]}\n")


def _inside_class(level_of_class_stackframe: int) -> bool:
    """Taichi's ``kernel_impl._inside_class``: whether the decorated function is defined in a class body (the
    caller's line starts with ``class`` or ``@data_oriented``), read from ``linecache``."""
    from taichi.lang import kernel_impl  # noqa: PLC0415 - loaded with taichi

    try:
        frame = sys._getframe(level_of_class_stackframe)  # called where Taichi's own is: the same frame
    except ValueError:
        return False
    line = linecache.getline(frame.f_code.co_filename, frame.f_lineno).strip()
    return any(pattern.match(line) for pattern in kernel_impl._KERNEL_CLASS_STACKFRAME_STMT_RES)


def quick_front_end() -> bool:
    """Replace the two slow, IR-neutral parts of Taichi's kernel front end (module docstring); True if replaced
    (only Taichi versions of ``FRONT_END_VERSIONS``; the positions only outside debug mode)."""
    if tuple(ti.__version__[:2]) not in FRONT_END_VERSIONS:
        return False
    from taichi.lang import kernel_impl  # noqa: PLC0415 - loaded with taichi
    from taichi.lang.ast import ast_transformer_utils  # noqa: PLC0415

    kernel_impl._inside_class = _inside_class
    if not _debug():
        ast_transformer_utils.ASTTransformerContext.get_pos_info = _position
    return True


quick_front_end()

_lock = threading.RLock()
_state: dict = {"arch": None, "threads": None}
# owner -> its argument packs in the current runtime (``argpacks``); emptied before every ``ti.init`` and at exit
_packs: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
# A pack freed after Taichi's modules are torn down at exit prints an ignored TypeError: free them first.
atexit.register(_packs.clear)


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
        _packs.clear()  # freed in the runtime that made them, before ti.init replaces it
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
                # matrices stay LLVM vectors: packed SIMD code, a cold compile ~5x faster (docs/platform.md §2)
                real_matrix_scalarize=False,
                debug=_debug(),
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


def argpacks(owner, build: Callable[[], dict]) -> dict:
    """``owner``'s argument packs (name -> ``ti.types.argpack`` instance) in the current runtime: ``build()`` at the
    first call and again after a re-initialisation; freed with ``owner``. Call it under the owner's launch lock,
    after ``use_arch``, and keep no pack beyond the launch (a kept one would outlive its runtime)."""
    with _lock:
        packs = _packs.get(owner)
        if packs is None:
            packs = _packs[owner] = build()
        return packs


def threads() -> int | None:
    """Taichi's CPU thread count in this process (None before the first initialisation)."""
    return _state["threads"]


def current_arch() -> str | None:
    """"cpu" or "cuda" after an initialisation, else None."""
    return _state["arch"]
