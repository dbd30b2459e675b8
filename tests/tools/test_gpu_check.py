"""The prepared GPU check (tools/gpu/gpu_check.py) on the CPU: its dry run goes end to end at 64x48, a failing or
overrunning step is recorded and the next one still runs, a spent budget skips steps, and without CUDA it stops at
once with exit status 2. Oracles: the step contract in the script's docstring (JSON keys, ok / FAIL / SKIPPED, exit
statuses) and a stand-in ``compute-sanitizer`` that runs the payload and writes a clean summary."""

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
# stand-in: compute-sanitizer --tool T --error-exitcode N --log-file F CMD... -> runs CMD, writes a clean summary
log=""
while [ $# -gt 0 ]; do case "$1" in --log-file) log=$2; shift 2;; --tool|--error-exitcode) shift 2;; *) break;; esac; done
"$@"; rc=$?
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


@pytest.mark.slow
def test_dry_run_with_a_sanitizer(tmp_path):
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    fake = bin_dir / "compute-sanitizer"
    fake.write_text(FAKE_SANITIZER)
    fake.chmod(0o755)
    done, report = _run(["--dry-run", "--steps", "env,compile,tp,memcheck"], tmp_path, bin_dir)
    assert done.returncode == 0, done.stderr[-2000:]
    steps = report["steps"]
    assert list(steps) == ["env", "compile", "tp", "memcheck"] and all(s["ok"] is True for s in steps.values())
    assert len(steps["compile"]["compile_s"]) == 5  # frames, convert, correlate, fused, texture
    assert set(steps["tp"]["runs"]) == {"64x48_graph_off", "64x48_graph_on"}
    assert all(r["process_ms"]["median"] > 0 and len(r["measure_ms"]["runs"]) == 2 for r in steps["tp"]["runs"].values())
    assert steps["memcheck"]["summary"] == ["========= ERROR SUMMARY: 0 errors"]
    assert "sanitizer payload done" in steps["memcheck"]["payload_stdout"]
    assert (tmp_path / "out" / "gpu_check.txt").read_text().startswith("tpnet-gpu GPU check")


@pytest.mark.slow
def test_dry_run_every_step(gpu_check, tmp_path):
    done, report = _run(["--dry-run"], tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    steps = report["steps"]
    assert list(steps) == list(gpu_check.STEPS)
    assert all(s["ok"] for n, s in steps.items() if n not in ("memcheck", "racecheck"))
    assert all(steps[n]["ok"] is not False for n in ("memcheck", "racecheck"))  # skipped where the tool is missing
    assert steps["pipeline_2592x1936"]["size"] == "64x48" and steps["pipeline_2592x1936"]["scene"] == "random"
    assert set(steps["pipeline_640x480"]["stages_ms"]) == {"engine search", "engine refine", "network", "texture",
                                                            "rest"}
    assert steps["tests"]["tests"] > 0 and steps["tests"]["failed"] == 0


def test_without_the_device_it_stops_at_once(tmp_path):
    pytest.importorskip("torch")
    import torch

    if torch.cuda.is_available():
        pytest.skip("this machine has CUDA")
    start = time.monotonic()
    done, report = _run(["--device", "cuda"], tmp_path)
    assert done.returncode == 2 and time.monotonic() - start < 60
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
