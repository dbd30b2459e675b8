"""The memory budget (``runtime.memory``) and the search's estimate (``disparity.budget.search_bytes``).
Oracles: the bytes of the tensors an engine really holds for its range (``Tensor.nbytes``), and the budget arithmetic on
a stated amount of available memory. A refusal must come before anything range-sized exists (timed < 10 s)."""

import time

import pytest

from tpnet_gpu.cli import main
from tpnet_gpu.config import EngineConfig, PipelineConfig
from tpnet_gpu.disparity import budget
from tpnet_gpu.disparity.engine import DisparityEngine
from tpnet_gpu.io import rigfile
from tpnet_gpu.pipeline import Pipeline
from tpnet_gpu.runtime import memory


def test_the_estimate_is_the_bytes_the_engine_holds_for_its_range():
    engine = DisparityEngine(96, 128, cfa=None, max_disparity=20.0, device="cpu")
    held = sum(t.nbytes for v in (engine.volume, engine.sparse_volume) for t in (v.values, v._cost, v._total))
    assert budget.search_bytes(96, 128, engine.d_min, engine.d_max, engine.config) == held


def test_budget_is_the_limit_given_or_a_share_of_what_is_available(monkeypatch):
    monkeypatch.setattr(memory, "available_bytes", lambda device="cpu": 10e9)
    assert memory.limit_bytes(None) == pytest.approx(memory.DEFAULT_SHARE * 10e9)
    assert memory.limit_bytes(2.5) == 2.5e9
    memory.check(7.9e9, None, "cpu", "work")  # within 80 % of 10 GB
    with pytest.raises(ValueError, match=r"^memory_limit_gb: work needs about 8.1 GB, more than the run's budget of "
                                         r"8.0 GB \(80 % of the 10.0 GB available\)"):
        memory.check(8.1e9, None, "cpu", "work")
    with pytest.raises(ValueError, match=r"budget of 1.0 GB \(memory_limit_gb=1\)"):
        memory.check(1.1e9, 1.0, "cpu", "work")
    monkeypatch.setattr(memory, "available_bytes", lambda device="cpu": None)
    memory.check(1e15, None, "cpu", "work")  # unknown: not refused


def test_available_memory_is_read_from_the_machine():
    free = memory.available_bytes("cpu")
    assert free is None or 1e6 < free < 1e15


def test_a_range_too_wide_for_the_budget_is_refused_before_any_work():
    rig = rigfile.load("binocular")
    from dataclasses import replace

    big = replace(rig, width=4000, height=3000, _cache={})
    config = PipelineConfig(engine=EngineConfig(memory_limit_gb=4.0))
    start = time.perf_counter()
    with pytest.raises(ValueError, match=r"memory_limit_gb: searching 0..2000 px .* over the 4000x3000 frame "
                                         r"\(2 engines: the cross-check's too\) with the frame's own buffers "
                                         r"needs about 25.7 GB"):
        Pipeline(3000, 4000, rig=big, cfa=None, max_disparity=2000.0, device="cpu", config=config)
    assert time.perf_counter() - start < 10.0
    with pytest.raises(ValueError, match="memory_limit_gb: expected a finite number of GB > 0"):
        EngineConfig(memory_limit_gb=float("nan"))


def test_cli_memory_limit_is_one_line(tmp_path, capsys):
    import numpy as np

    from tpnet_gpu.io.images import save_png

    image = (np.random.default_rng(0).random((48, 64)) * 255).astype(np.uint8)
    save_png(tmp_path / "l.png", image)
    save_png(tmp_path / "r.png", np.roll(image, -2, axis=1))
    args = ["process", str(tmp_path / "l.png"), str(tmp_path / "r.png"), "--max-disparity", "30", "--out",
            str(tmp_path / "o"), "--no-figures"]
    assert main([*args, "--memory-limit", "1e-6"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "memory_limit_gb: searching 0..30 px" in err[0], err
    assert "--memory-limit GB" in err[0]
    with pytest.raises(SystemExit) as done:  # argparse's own refusal of an option value
        main([*args, "--memory-limit", "inf"])
    assert done.value.code == 2
    assert "argument --memory-limit: expected a finite number of GB > 0, got 'inf'" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
