"""``tpnet bench two_surface`` end to end at a tiny size. Oracle: the report layout bench_two_surface documents (its
totals' keys, the per-scene counts summing to them) and the same report written as JSON."""

import json

from tpnet_gpu import cli
from tpnet_gpu.bench.accuracy import bench_two_surface

TOTALS = {"edge_two_surface_tiles", "reported_two", "both", "either_of_two", "single_either",
          "single_either_where_two", "flat_tiles", "flat_reported_two"}


def test_bench_two_surface_tiny(tmp_path, capsys):
    path = tmp_path / "ts.json"
    report = bench_two_surface.main(["--width", "96", "--height", "72", "--scenes", "1", "--supersample", "1",
                                     "--backend", "warp", "--json", str(path)])
    assert json.loads(path.read_text()) == json.loads(json.dumps(report, default=float))
    assert set(report["totals"]) == TOTALS
    assert all(report["totals"][k] == sum(s[k] for s in report["per_scene"]) for k in TOTALS)
    assert report["totals"]["both"] <= report["totals"]["reported_two"] <= report["totals"]["edge_two_surface_tiles"]
    assert report["totals"]["single_either_where_two"] <= min(report["totals"]["single_either"],
                                                              report["totals"]["reported_two"])
    assert "both within 0.5 px" in capsys.readouterr().out
    assert "two_surface" in cli.bench.BENCHES
