"""Taichi set-up (tpnet_gpu/runtime/taichi_setup.py): the offline cache folder, the CPU thread count, bad arguments.
Oracles: the folder the cache files appear in and the thread count Taichi reports, in a fresh process."""

import os
import subprocess
import sys
import textwrap

import pytest

from tpnet_gpu.runtime import taichi_setup


def test_cache_dir_follows_tpnet_cache_dir(monkeypatch, tmp_path):
    monkeypatch.setenv("TPNET_CACHE_DIR", str(tmp_path))
    assert taichi_setup.cache_dir() == tmp_path / "taichi"
    monkeypatch.delenv("TPNET_CACHE_DIR")
    assert taichi_setup.cache_dir().parts[-3:] == (".cache", "tpnet-gpu", "taichi")


def test_threads_and_cache_in_a_fresh_process(tmp_path):
    script = tmp_path / "init_run.py"
    script.write_text(textwrap.dedent("""
        import taichi as ti
        from tpnet_gpu.runtime import taichi_setup
        taichi_setup.init_taichi("cpu")
        print("threads", ti.lang.impl.current_cfg().cpu_max_num_threads, taichi_setup.threads())
    """))
    env = {**os.environ, "TPNET_CACHE_DIR": str(tmp_path / "cache"), "TPNET_TAICHI_THREADS": "1"}
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "threads 1 1" in done.stdout
    assert "[Taichi]" not in done.stdout  # no banner on stdout
    assert list((tmp_path / "cache" / "taichi").glob("*.tic"))  # the offline cache went to the stable folder


def test_bad_thread_counts(monkeypatch):
    monkeypatch.setenv("TPNET_TAICHI_THREADS", "many")
    with pytest.raises(ValueError, match="TPNET_TAICHI_THREADS: expected a positive number of threads, got 'many'"):
        taichi_setup._threads_from_env()
    monkeypatch.delenv("TPNET_TAICHI_THREADS")
    with pytest.raises(ValueError, match="threads: expected a positive number of threads, got 0"):
        taichi_setup.init_taichi("cpu", threads=0)
    taichi_setup.init_taichi("cpu")
    other = taichi_setup.threads() + 1
    with pytest.raises(ValueError, match=f"threads: Taichi already runs {other - 1} CPU threads in this process, got {other}"):
        taichi_setup.init_taichi("cpu", threads=other)


def test_bad_arch():
    with pytest.raises(ValueError, match=r"arch: expected one of \('cpu', 'cuda'\), got 'vulkan'"):
        taichi_setup.init_taichi("vulkan")


def test_argument_packs_are_made_again_after_a_reinitialisation(tmp_path):
    """A processor's argument packs live in one Taichi runtime (taichi_setup.argpacks): after a re-initialisation
    (another arch in between, simulated on the CPU) its next call makes them again, and none is freed after
    Taichi's modules at exit. Oracle: the same processor's correlations before the re-initialisation (bit-equal),
    and an exit without an ignored exception on stderr."""
    script = tmp_path / "reinit_run.py"
    script.write_text(textwrap.dedent("""
        import numpy as np
        import torch
        from tpnet_gpu.runtime import taichi_setup
        from tpnet_gpu.processor import TileProcessor
        frames = np.random.default_rng(1).uniform(0, 4000, (4, 32, 48)).astype(np.float32)
        tp = TileProcessor(32, 48, textures=True, device="cpu", backend="taichi")
        first = tp.process(frames, 1.0).corr.clone()
        taichi_setup._state["arch"] = None  # as after a run on another arch
        taichi_setup.init_taichi("cpu")
        print("equal", torch.equal(first, tp.process(frames, 1.0).corr), bool(first.any()))
    """))
    env = {**os.environ, "TPNET_TAICHI_THREADS": "1"}
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=600, env=env)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "equal True True" in done.stdout
    assert "Exception ignored" not in done.stderr, done.stderr[-2000:]
