"""``tpnet bench calibration`` end to end at a tiny size (bench/accuracy/bench_calibration.py): ``main(argv)`` prints its
table and writes the same report as JSON. Oracle: the report layout the bench documents (its keys), every rig's
disparity statistics, and the ideal rig's edge error equal to the misalignment asked for (1 %)."""

import json

import pytest

TINY = ["--width", "96", "--height", "64", "--levels", "1.0", "--scenes", "1", "--rounds", "1",
        "--gradient-steps", "1"]


@pytest.mark.slow
def test_calibration_bench_smoke(tmp_path, capsys):
    from tpnet_gpu.bench.accuracy import bench_calibration

    path = tmp_path / "calibration.json"
    report = bench_calibration.main([*TINY, "--json", str(path)])
    out = capsys.readouterr().out
    assert "edge err LMA" in out and "flat gross % / inlier RMSE px" in out
    assert json.loads(path.read_text())["table"] == report["table"]
    (level,) = report["levels"]
    assert set(level) >= {"level_px", "truth", "edge_px", "seconds", "rounds", "disparity"}
    assert set(level["disparity"]) == set(bench_calibration.RIGS)
    assert abs(level["edge_px"]["ideal"] - 1.0) < 0.01
    assert set(level["edge_px"]) == {"ideal", "lma", "gradient"}
