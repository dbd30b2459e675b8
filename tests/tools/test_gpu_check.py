"""The prepared GPU check (tools/gpu/gpu_check.py) on the CPU: its dry run goes end to end at 64x48, a failing or
overrunning step is recorded and the next one still runs, a spent budget skips steps, ``--steps`` runs only the
steps named, a missing sanitizer skips its steps, and without CUDA it stops at once with exit status 2. Oracles: the
step contract in the script's docstring (JSON keys, ok / FAIL / SKIPPED, exit statuses) and a stand-in
``compute-sanitizer`` that runs the payload (for memcheck; racecheck's stand-in only writes its summary) and writes a
clean summary. One dry run of every step serves the two dry-run tests (a run costs ~40 s on 2 cores)."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "tools" / "gpu" / "gpu_check.py"
FAKE_SANITIZER = """#!/bin/sh
# stand-in: compute-sanitizer --tool T --error-exitcode N --log-file F CMD... -> runs CMD (memcheck only: the
# payload once is enough), writes a clean summary
log=""; tool=""
while [ $# -gt 0 ]; do case "$1" in --log-file) log=$2; shift 2;; --tool) tool=$2; shift 2;; --error-exitcode) shift 2;;
  *) break;; esac; done
rc=0
if [ "$tool" = memcheck ]; then "$@"; rc=$?; fi
echo "========= ERROR SUMMARY: 0 errors" > "$log"
exit $rc
"""


@pytest.fixture(scope="module")
def gpu_check():
    spec = importlib.util.spec_from_file_location("gpu_check", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _run(args, tmp_path, extra_path=None) -> tuple[subprocess.CompletedProcess, dict]:
    env = dict(os.environ)
    if extra_path is not None:
        env["PATH"] = f"{extra_path}{os.pathsep}{env['PATH']}"
    done = subprocess.run([sys.executable, str(SCRIPT), "--out", str(tmp_path / "out"), *args], capture_output=True,
                          text=True, env=env, timeout=600)
    return done, json.loads((tmp_path / "out" / "gpu_check.json").read_text())


@pytest.fixture(scope="module")
def dry_run(tmp_path_factory) -> tuple[subprocess.CompletedProcess, dict, Path]:
    """One ``--dry-run`` of every step with the stand-in sanitizer on PATH: (process, report, out folder)."""
    tmp_path = tmp_path_factory.mktemp("dry_run")
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    fake = bin_dir / "compute-sanitizer"
    fake.write_text(FAKE_SANITIZER)
    fake.chmod(0o755)
    done, report = _run(["--dry-run"], tmp_path, bin_dir)
    return done, report, tmp_path / "out"


@pytest.mark.slow
def test_dry_run_with_a_sanitizer(dry_run):
    done, report, out = dry_run
    assert done.returncode == 0, done.stderr[-2000:]
    steps = report["steps"]
    assert all(steps[n]["ok"] is True for n in ("env", "compile", "tp", "memcheck", "racecheck"))
    assert len(steps["compile"]["compile_s"]) == 5  # frames, convert, correlate, fused, texture
    assert set(steps["tp"]["runs"]) == {"64x48_graph_off", "64x48_graph_on"}
    assert all(r["process_ms"]["median"] > 0 and len(r["measure_ms"]["runs"]) == 2 for r in steps["tp"]["runs"].values())
    for tool in ("memcheck", "racecheck"):
        assert steps[tool]["summary"] == ["========= ERROR SUMMARY: 0 errors"], tool
    assert "sanitizer payload done" in steps["memcheck"]["payload_stdout"]
    assert (out / "gpu_check.txt").read_text().startswith("tpnet-gpu GPU check")


@pytest.mark.slow
def test_dry_run_every_step(gpu_check, dry_run):
    done, report, _ = dry_run
    assert done.returncode == 0, done.stderr[-2000:]
    steps = report["steps"]
    assert list(steps) == list(gpu_check.STEPS)
    assert all(s["ok"] for s in steps.values())
    assert steps["pipeline_2592x1936"]["size"] == "64x48" and steps["pipeline_2592x1936"]["scene"] == "random"
    assert set(steps["pipeline_640x480"]["stages_ms"]) == {"engine search", "engine refine", "network", "texture",
                                                            "rest"}
    assert steps["tests"]["tests"] > 0 and steps["tests"]["failed"] == 0


def test_steps_runs_only_those_named_and_a_missing_sanitizer_skips(gpu_check, tmp_path, monkeypatch):
    # In this process (the env step and the sanitizer's look-up are cheap): the named steps in the given order.
    _keep_cache_env(monkeypatch)
    monkeypatch.setattr(gpu_check.gs, "find_sanitizer", lambda: None)
    assert gpu_check.main(["--out", str(tmp_path), "--dry-run", "--steps", "racecheck,env"]) == 0
    steps = json.loads((tmp_path / "gpu_check.json").read_text())["steps"]
    assert list(steps) == ["racecheck", "env"] and steps["env"]["ok"] is True
    assert steps["racecheck"]["ok"] is None and "compute-sanitizer not found" in steps["racecheck"]["skipped"]


def _keep_cache_env(monkeypatch) -> None:
    """``gpu_check.main`` in this process sets the kernel caches' variables when absent: restored after the test."""
    for name, default in (("WARP_CACHE_PATH", "/tmp/warp-cache"), ("TPNET_CACHE_DIR", "/tmp/tpnet-cache")):
        monkeypatch.setenv(name, os.environ.get(name, default))


def test_without_the_device_it_stops_at_once(gpu_check, tmp_path, monkeypatch):
    pytest.importorskip("torch")
    import torch

    if torch.cuda.is_available():
        pytest.skip("this machine has CUDA")
    _keep_cache_env(monkeypatch)
    start = time.monotonic()  # in this process (the dry run checks the script's exit status as a program)
    assert gpu_check.main(["--device", "cuda", "--out", str(tmp_path / "out")]) == 2 and time.monotonic() - start < 60
    report = json.loads((tmp_path / "out" / "gpu_check.json").read_text())
    assert list(report["steps"]) == ["env"]
    assert report["steps"]["env"]["ok"] is False and "no CUDA" in report["steps"]["env"]["error"]


def test_a_failing_or_overrunning_step_is_recorded_and_the_next_runs(gpu_check, tmp_path, monkeypatch):
    monkeypatch.setattr(gpu_check, "MIN_BOX", 0)
    monkeypatch.setitem(gpu_check.BOXES, "slow", 1)
    check = gpu_check.Check(tmp_path, 60, {"device": "cpu", "device_name": "test"})

    def boom(box):
        raise RuntimeError("illegal memory access")

    check.step("boom", boom)
    check.step("slow", lambda box: time.sleep(5))
    check.step("fine", lambda box: {"summary": ["all good"]})
    steps = json.loads((tmp_path / "gpu_check.json").read_text())["steps"]
    assert steps["boom"]["ok"] is False and "RuntimeError: illegal memory access" in steps["boom"]["error"]
    assert steps["slow"]["ok"] is False and "StepTimeout" in steps["slow"]["error"] and steps["slow"]["seconds"] < 3
    assert steps["fine"]["ok"] is True
    text = (tmp_path / "gpu_check.txt").read_text()
    assert "boom                 FAIL" in text and "    all good" in text


def test_a_spent_budget_skips_steps(gpu_check, tmp_path):
    check = gpu_check.Check(tmp_path, 5, {"device": "cpu", "device_name": "test"})
    entry = check.step("env", lambda box: pytest.fail("must not run"))
    assert entry["ok"] is None and "budget spent" in entry["skipped"]
