"""``tpnet bench flow`` end to end at a tiny size. Oracle: the report layout bench_flow documents (its keys, one row
per motion and flow source) and the same report written as JSON; ``tpnet bench flow`` reaches the same main."""

import json

from tpnet_gpu import cli
from tpnet_gpu.bench.accuracy import bench_flow

ROW = {"median", "rmse_inliers", "gross", "coverage", "tiles"}


def test_bench_flow_tiny(tmp_path, capsys):
    path = tmp_path / "flow.json"
    report = bench_flow.main(["--width", "64", "--height", "48", "--scenes", "1", "--motions", "roll 10 mrad",
                              "--json", str(path)])
    assert json.loads(path.read_text()) == json.loads(json.dumps(report, default=float))
    assert set(report["stats"]) == {"roll 10 mrad | camera 0", "roll 10 mrad | camera 0, one way",
                                    "roll 10 mrad | 4 cameras"}
    assert all(set(row) == ROW for row in report["stats"].values())
    assert "median px" in capsys.readouterr().out
    assert "flow" in cli.bench.BENCHES
