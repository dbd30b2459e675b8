"""CUDA compile check that needs no GPU: every Warp kernel module of ``tpnet_gpu.kernels`` is built to a cubin.

Why: CI has no GPU, yet the kernels must stay compilable for CUDA (issue 12). Warp's wheel bundles NVRTC, so
``wp.compile_aot_module(module, arch=90, use_ptx=False)`` builds sm_90 code on a CPU-only machine, no driver needed.

What: the modules are found, not listed: each ``tpnet_gpu.kernels.*`` module but the ``taichi_*`` twins is imported
and kept when Warp registered ``@wp.kernel``s for it. Each is compiled per arch at ``layout.CUDA_BLOCK_DIM``, the
block size of every CUDA launch (Warp builds a module once per block_dim), in its own subprocess (``jobs`` at a time,
default one per core). A compile's report - per kernel: registers, stack frame and static shared memory read off the
cubin's ELF sections (tpnet_gpu.runtime.cubin), dynamic shared memory (Warp's tile storage) from the module's ``.meta`` - is the
stamp ``report.json`` beside the cubin in ``$TPNET_CACHE_DIR/cuda-aot/warp-<version>/<key>/`` (default
``~/.cache/tpnet-gpu``), ``<key> = <module>.sm<arch>.bd<block_dim>.<hash>``, where ``<hash>`` is Warp's content hash
of the module at that block_dim (its kernels, the ``@wp.func``s they call in any module, the module options). An
unchanged tree is checked in about a second; an edited kernel recompiles its module only. Failures are not cached.

    python -m tpnet_gpu.runtime.cuda_aot [--arch 90] [--arch 80] [--jobs N] [--json FILE]   # exit status 1: a module failed
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import os
import pkgutil
import re
import shutil
import subprocess
import sys
import tempfile
import time
import traceback
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import warp as wp

from tpnet_gpu.runtime.cubin import kernel_resources
from tpnet_gpu.layout import CUDA_BLOCK_DIM
from tpnet_gpu.runtime.warp_setup import init_warp

PACKAGE = "tpnet_gpu.kernels"
ROW_TAG = "CUDA_AOT_ROW "
NO_DRIVER = "Warp CUDA warning: Could not find or load the NVIDIA CUDA driver"  # expected here: not the error
TIMEOUT_S = 1800  # one module's compile; the largest takes ~20 s of one core


def cache_root() -> Path:
    """``$TPNET_CACHE_DIR/cuda-aot/warp-<version>`` (default ``~/.cache/tpnet-gpu``): another Warp, another cache."""
    root = os.environ.get("TPNET_CACHE_DIR") or str(Path.home() / ".cache" / "tpnet-gpu")
    return Path(root) / "cuda-aot" / f"warp-{wp.__version__}"


def nvrtc_problem(archs: list[int]) -> str | None:
    """Why Warp's NVRTC cannot build ``archs`` here, or None when it can (a CPU-only machine can)."""
    try:
        init_warp()
        supported = wp.get_cuda_supported_archs()
    except Exception as e:  # noqa: BLE001 - any failure to load Warp's CUDA side is the reason
        return f"Warp's CUDA toolchain (NVRTC) failed to load: {e}"
    if not supported:
        return f"Warp {wp.__version__} has no NVRTC (built without CUDA, or its CUDA library did not load)"
    missing = [a for a in archs if a not in supported]
    targets = ", ".join(f"sm_{a}" for a in missing)
    return f"Warp's NVRTC cannot target {targets}; it supports sm_{supported}" if missing else None


def kernel_modules(package: str = PACKAGE) -> list[str]:
    """Names of the modules of ``package`` (not ``taichi_*``) that define Warp kernels, sorted."""
    init_warp()
    pkg = importlib.import_module(package)
    names = []
    for info in pkgutil.iter_modules(pkg.__path__, package + "."):
        if info.name.rpartition(".")[2].startswith("taichi_"):
            continue
        importlib.import_module(info.name)
        if wp.get_module(info.name).kernels:
            names.append(info.name)
    return sorted(names)


def module_key(name: str, arch: int, block_dim: int = CUDA_BLOCK_DIM) -> str:
    """Cache key of one compile: module, arch, block_dim and Warp's content hash of the module at that block_dim."""
    init_warp()
    importlib.import_module(name)
    digest = wp.get_module(name).get_module_hash(block_dim=block_dim).hex()
    return f"{name}.sm{arch}.bd{block_dim}.{digest[:16]}"


def _kernel_table(cubin: Path) -> dict:
    """{kernel: {registers, stack, static_smem, dynamic_smem}}, names without Warp's hash suffix."""
    meta = json.loads(next(cubin.parent.glob("*.meta")).read_text())
    table = {}
    for symbol, values in sorted(kernel_resources(cubin.read_bytes()).items()):
        m = re.fullmatch(r"(.+?)(?:_[0-9a-f]{8})?_cuda_kernel_(forward|backward)", symbol)
        name = m[1] + ("" if m[2] == "forward" else ".backward") if m else symbol
        table[name] = {"registers": 0, "stack": 0, "static_smem": 0, **values,
                       "dynamic_smem": meta.get(symbol + "_smem_bytes", 0)}
    return table


def _error_text(e: BaseException) -> str:
    text = "".join(traceback.format_exception_only(type(e), e)).strip()
    cause = e.__cause__ or e.__context__
    return text + (" <- " + _error_text(cause) if cause is not None else "")


def compile_module(name: str, arch: int, block_dim: int, root: Path) -> dict:
    """Compile one module in this process: its report row, on success also the stamp ``<root>/<key>/report.json``."""
    key = module_key(name, arch, block_dim)
    row = {"module": name, "arch": arch, "block_dim": block_dim, "key": key, "ok": False, "cached": False}
    root.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=".build-", dir=root))  # renamed to <key> when complete: no half stamps
    start = time.perf_counter()
    try:
        wp.set_module_options({"block_dim": block_dim}, module=name)
        paths = wp.compile_aot_module(name, arch=arch, use_ptx=False, module_dir=str(work))
        row["kernels"] = _kernel_table(Path(paths[-1]))
        row["ok"] = True
    except Exception as e:  # noqa: BLE001 - reported verbatim (NVRTC's log goes to this process's output)
        row["error"] = _error_text(e)
    row["seconds"] = round(time.perf_counter() - start, 1)
    if row["ok"]:
        (work / "report.json").write_text(json.dumps(row, indent=1))
        with contextlib.suppress(OSError):  # fails only when a concurrent check finished it first
            work.rename(root / key)
    shutil.rmtree(work, ignore_errors=True)
    return row


def _run_worker(name: str, arch: int, block_dim: int, root: Path) -> dict:
    """Compile one module in a subprocess (NVRTC is single-threaded per module); its output explains a failure."""
    cmd = [sys.executable, "-m", "tpnet_gpu.runtime.cuda_aot", "--worker", name, str(arch), str(block_dim), str(root)]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}  # same imports as this process
    row = {"module": name, "arch": arch, "block_dim": block_dim, "ok": False, "cached": False}
    start = time.perf_counter()
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=TIMEOUT_S)
        output = done.stdout + "\n" + done.stderr
    except subprocess.TimeoutExpired as e:
        return {**row, "seconds": TIMEOUT_S, "error": f"compile timed out after {TIMEOUT_S} s: {e}"}
    found = [json.loads(line[len(ROW_TAG):]) for line in done.stdout.splitlines() if line.startswith(ROW_TAG)]
    row = found[0] if found else {**row, "seconds": round(time.perf_counter() - start, 1),
                                  "error": f"worker exited with status {done.returncode}"}
    if not row["ok"]:
        log = "\n".join(line for line in output.splitlines() if not line.startswith((ROW_TAG, NO_DRIVER))).strip()
        row["error"] += "\n" + log[:8000] + (" [...]" if len(log) > 8000 else "")  # NVRTC's message, first error first
    return row


def check(archs: list[int] | tuple[int, ...] = (90,), block_dim: int = CUDA_BLOCK_DIM,
          modules: list[str] | None = None, jobs: int | None = None, root: Path | None = None) -> list[dict]:
    """Compile ``modules`` (default: every kernel module) for each arch, cached: one report row per module x arch.

    Raises RuntimeError naming NVRTC when Warp cannot compile for CUDA here."""
    problem = nvrtc_problem(list(archs))
    if problem:
        raise RuntimeError(problem)
    root = root or cache_root()
    modules = kernel_modules() if modules is None else modules
    rows, todo = {}, []
    for arch in archs:
        for name in modules:
            stamp = root / module_key(name, arch, block_dim) / "report.json"
            if stamp.exists():
                rows[name, arch] = {**json.loads(stamp.read_text()), "cached": True}
            else:
                todo.append((name, arch))
    with ThreadPoolExecutor(max_workers=max(1, jobs or os.cpu_count() or 1)) as pool:
        for (name, arch), row in zip(todo, pool.map(lambda t: _run_worker(*t, block_dim, root), todo)):
            rows[name, arch] = row
    return [rows[name, arch] for arch in archs for name in modules]


def format_table(rows: list[dict]) -> str:
    """One line per kernel: module, arch, block, ok, compile seconds, cached, registers and shared memory."""
    lines = [f"{'module':28s} {'arch':5s} {'block':>5s} {'ok':4s} {'comp s':>6s} {'cached':6s}  {'kernel':20s} "
             f"{'regs':>4s} {'stack B':>7s} {'smem static B':>13s} {'smem dyn B':>10s}"]
    for r in rows:
        head = (f"{r['module']:28s} sm_{r['arch']:<2d} {r['block_dim']:5d} {'OK' if r['ok'] else 'FAIL':4s} "
                f"{r.get('seconds', 0):6.1f} {'yes' if r['cached'] else 'no':6s}")
        for i, (k, v) in enumerate((r.get("kernels") or {"-": {}}).items()):
            lines.append(f"{head if i == 0 else ' ' * len(head)}  {k:20s} {v.get('registers', ''):>4} "
                         f"{v.get('stack', ''):>7} {v.get('static_smem', ''):>13} {v.get('dynamic_smem', ''):>10}")
        if not r["ok"]:
            lines.append("    ERROR: " + r.get("error", "").replace("\n", "\n    "))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m tpnet_gpu.runtime.cuda_aot", description=__doc__.split("\n\n")[0])
    p.add_argument("--arch", type=int, action="append", help="target SM version, repeatable (default 90)")
    p.add_argument("--block-dim", type=int, default=CUDA_BLOCK_DIM, help="threads per block (default: CUDA's)")
    p.add_argument("--jobs", type=int, default=None, help="parallel compiles (default: one per core)")
    p.add_argument("--json", default="", help="also write the report rows to this file")
    p.add_argument("--worker", nargs=4, help=argparse.SUPPRESS)  # MODULE ARCH BLOCK_DIM ROOT: one compile, here
    a = p.parse_args(argv)
    if a.worker:
        name, arch, block_dim, root = a.worker
        row = compile_module(name, int(arch), int(block_dim), Path(root))
        print(ROW_TAG + json.dumps(row), flush=True)
        return 0
    start = time.perf_counter()
    try:
        rows = check(a.arch or [90], a.block_dim, jobs=a.jobs)
    except RuntimeError as e:
        print(f"cuda_aot: {e}", file=sys.stderr)
        return 2
    print(format_table(rows))
    failed = sum(not r["ok"] for r in rows)
    print(f"{len(rows)} compiles, {sum(r['cached'] for r in rows)} cached, {failed} failed, "
          f"{time.perf_counter() - start:.1f} s; cache {cache_root()}")
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))
    return int(failed > 0)


if __name__ == "__main__":
    sys.exit(main())
