"""Shared by every bench: timing, machine information, progress logging to stderr, JSON reports, text tables, the
speed benches' frame options, and the entry-point runner (``run``) behind ``python -m`` and ``tpnet bench``."""

from __future__ import annotations

import argparse
import importlib
import json
import logging
import os
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Callable

import numpy as np

from tpnet_gpu import tables

# Filippov & Dzhimiev, "See far with TPNET": the whole tile processor, one full quad frame, on a GTX 1050 Ti.
PAPER_TP_MS = 87.0
PAPER_GPU = "GTX 1050 Ti"

# Imports of the optional ``bench`` extra (pyproject.toml) -> what to install.
EXTRAS = {"cv2": "opencv-python-headless", "matplotlib": "matplotlib"}
EXTRA_HINT = 'pip install -e ".[bench]"'

RAW_VALUES = "uniform integers 0..4095 as float32"  # the speed benches' random frames
THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


# --- progress log -----------------------------------------------------------------------------------------------
class _Stderr(logging.StreamHandler):
    """Writes to whatever ``sys.stderr`` is when a record is emitted (pytest and callers may swap it)."""

    def __init__(self) -> None:
        super().__init__(sys.stderr)

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, _value) -> None:
        pass


class _BenchFormatter(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        return f"[{record.name.rpartition('.')[2]}] {record.getMessage()}"


_ROOT = logging.getLogger(__package__)  # tpnet_gpu.bench
if not _ROOT.handlers:
    _handler = _Stderr()
    _handler.setFormatter(_BenchFormatter())
    _ROOT.addHandler(_handler)
    _ROOT.setLevel(logging.INFO)
    _ROOT.propagate = False  # progress lines go to stderr once, whatever the root logger does


def logger(bench: str) -> Callable[[str], None]:
    """``log(message)``: a progress line ``[bench] message`` on stderr (logger ``tpnet_gpu.bench.<bench>``)."""
    return logging.getLogger(f"{__package__}.{bench}").info


# --- timing -----------------------------------------------------------------------------------------------------
def timed_ms(fn: Callable[[], None], sync: Callable[[], None] | None = None) -> float:
    """Wall-clock milliseconds of ``fn()``, with ``sync()`` (a device synchronisation) before the timer stops."""
    start = time.perf_counter()
    fn()
    if sync is not None:
        sync()
    return 1e3 * (time.perf_counter() - start)


def summary(runs: list[float]) -> dict:
    """Median, best and every run (ms)."""
    return {"median": statistics.median(runs), "best": min(runs), "runs": runs}


# --- machine ----------------------------------------------------------------------------------------------------
def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def device_name(device) -> str:
    """A Warp device in words: the GPU's name, or ``CPU (<model>)``."""
    return device.name if device.is_cuda else f"CPU ({cpu_model()})"


def machine_info(**extra) -> dict:
    """Platform, Python, CPU, library versions and the thread variables, plus ``extra`` (a bench's own notes)."""
    import torch
    import warp as wp

    return {"platform": platform.platform(), "python": platform.python_version(), "cpu_count": os.cpu_count(),
            "cpu_model": cpu_model(), "numpy": np.__version__, "warp": wp.__version__, "torch": torch.__version__,
            **extra, "thread_env": {k: os.environ.get(k) for k in THREAD_ENV}}


# --- output -----------------------------------------------------------------------------------------------------
def save_json(report: dict, path) -> Path:
    """Write a bench report as JSON (parent folder created); floats that JSON lacks become numbers."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(report, indent=1, default=float) + "\n")
    return path


def format_table(header, rows) -> list[str]:
    """Text table lines: a header, a rule, the rows; first column left-aligned, the others right-aligned."""
    widths = [max(len(r[i]) for r in list(rows) + [header]) for i in range(len(header))]
    line = " | ".join(f"{{:{'<' if i == 0 else '>'}{w}}}" for i, w in enumerate(widths))
    return [line.format(*header), "-+-".join("-" * w for w in widths)] + [line.format(*r) for r in rows]


# --- the speed benches' frames ----------------------------------------------------------------------------------
def frame_arguments(parser: argparse.ArgumentParser) -> None:
    """The speed benches' common options: device, frame size, repeats, target disparity, CFA, seed."""
    parser.add_argument("--device", default=None, help="Warp device: cpu, cuda, cuda:N (default: cuda if present)")
    parser.add_argument("--height", type=int, default=1936)
    parser.add_argument("--width", type=int, default=2592)
    parser.add_argument("--repeat", type=int, default=3, help="timed passes after the warm-up (default 3)")
    parser.add_argument("--disparity", type=float, default=2.5, help="target disparity of every tile, px")
    parser.add_argument("--cfa", default=tables.DEFAULT_CFA, help="Bayer pattern, or 'mono'")
    parser.add_argument("--seed", type=int, default=0)


def frame_cfa(parser: argparse.ArgumentParser, args: argparse.Namespace) -> str | None:
    """Checks the options of ``frame_arguments``; returns the CFA (None for mono)."""
    if args.repeat < 1:
        parser.error("--repeat: expected at least 1")
    return None if args.cfa.lower() == "mono" else args.cfa


def random_frames(rng: np.random.Generator, height: int, width: int, cams: int = len(tables.QUAD_OFFSETS)):
    """``(cams, height, width)`` float32 raw frames of ``RAW_VALUES``."""
    return rng.integers(0, 4096, size=(cams, height, width), dtype=np.uint16).astype(np.float32)


def frame_info(args: argparse.Namespace, cfa: str | None, cams: int, tiles: int, pairs: int) -> dict:
    """The ``frame`` entry of a speed bench's report."""
    return {"width": args.width, "height": args.height, "cameras": cams, "tiles": tiles, "pairs": pairs, "cfa": cfa,
            "target_disparity": args.disparity, "seed": args.seed, "raw_values": RAW_VALUES}


# --- entry points -----------------------------------------------------------------------------------------------
def prog(module: str) -> str:
    """The command of a bench module (``tpnet_gpu.bench.throughput.bench_tp`` -> ``tpnet bench tp``)."""
    if module == "__main__":  # python -m tpnet_gpu.bench.GROUP.bench_NAME
        spec = getattr(sys.modules["__main__"], "__spec__", None)
        module = spec.name if spec is not None else module
    return f"tpnet bench {module.rpartition('.')[2].removeprefix('bench_')}"


def parser(module: str, doc: str, *, full_help: bool = False) -> argparse.ArgumentParser:
    """A bench's argument parser: its command as ``prog``; the doc's first paragraph, or all of it (``full_help``)."""
    if full_help:
        return argparse.ArgumentParser(prog=prog(module), description=doc,
                                       formatter_class=argparse.RawDescriptionHelpFormatter)
    return argparse.ArgumentParser(prog=prog(module), description=doc.split("\n\n")[0])


class MissingExtra(SystemExit):
    """An optional dependency of the ``bench`` extra is not installed (a one-line message, no traceback)."""

    def __init__(self, module: str) -> None:
        super().__init__(f"this bench needs {EXTRAS.get(module, module)} (module {module}) of the optional 'bench' "
                         f"extra: {EXTRA_HINT}")


def require_extras(*modules: str) -> None:
    """Import ``modules`` of the ``bench`` extra now, before any work; raises ``MissingExtra`` for a missing one."""
    for module in modules:
        try:
            importlib.import_module(module)
        except ImportError:
            raise MissingExtra(module) from None


def run(main: Callable[[list[str] | None], dict], argv: list[str] | None = None) -> int:
    """Exit status of a bench's ``main(argv)``: 0 when it returns its report; argparse's status for ``--help`` and
    bad options; 2, with a one-line ``tpnet bench NAME: error: ...`` on stderr, for a message (a missing extra
    included)."""
    command = prog(main.__module__)
    try:
        main(argv)
    except ModuleNotFoundError as exc:  # a lazy import of the bench extra that require_extras did not cover
        root = (exc.name or "").partition(".")[0]
        if root not in EXTRAS:
            raise
        print(f"{command}: error: {MissingExtra(root).code}", file=sys.stderr)
        return 2
    except SystemExit as done:
        if isinstance(done.code, str):
            print(f"{command}: error: {done.code}", file=sys.stderr)
            return 2
        return int(done.code or 0)
    return 0


def parse_sizes(text: str, option: str) -> list[tuple[int, int]]:
    """Frame sizes of the option ``option``: ``"640x480,2592x1936"`` -> [(640, 480), (2592, 1936)] (width x
    height, multiples of 8, at least 16); '' -> []; ValueError naming ``option`` otherwise."""
    sizes = []
    for item in (s.strip() for s in text.split(",")):
        if not item:
            continue
        try:
            width, height = (int(v) for v in item.lower().split("x"))
        except ValueError:
            raise ValueError(f"{option}: expected WIDTHxHEIGHT[,WIDTHxHEIGHT...], got {text!r}") from None
        if width < 16 or height < 16 or width % 8 or height % 8:
            raise ValueError(f"{option}: expected multiples of 8, at least 16, got {item!r}")
        sizes.append((width, height))
    return sizes
