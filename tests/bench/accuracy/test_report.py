"""The accuracy benches' report (tpnet_gpu.bench.accuracy.report, bench/accuracy/report.py): statistics, per-frame costs and the
table from hand-made scenes. Oracle: rates hand-counted on two copies of a 4x5-tile scene whose six interior
tiles are all flat (ground truth 2 px, one surface, except tile 0 of the interior which also sees a surface at
4.2 px over 30 % of its window)."""

import numpy as np

from tpnet_gpu.bench.accuracy import report

REF, METHOD = "reference", "method"


def _interior(values) -> np.ndarray:
    """A (4, 5) tile grid: the ground truth (2 px) on the border, ``values`` (2x3) inside."""
    grid = np.full((4, 5), 2.0)
    grid[1:3, 1:4] = values
    return grid


def _scene(per_frame: dict, confidences: dict, surfaces: bool = True) -> dict:
    shape = (4, 5)
    tile_surfaces = np.full((*shape, 2, 3), np.nan)
    tile_surfaces[:, :, 0] = (1.0, 2.0, 2.0)
    tile_surfaces[1, 1, 1] = (0.3, 4.2, 4.2)
    scene = {"gt": np.full(shape, 2.0), "confidence": np.ones(shape), "spread": np.zeros(shape),
             # reference: right at interior tiles 0, 1, 3, 5 (4 of them), gross at 2, missing 4
             "estimates": {REF: _interior([[2.1, 2.0, 5.0], [2.0, np.nan, 2.2]]),
                           # method: gross at 0 (on the 4.2 px surface: either-right), 2 and 3; missing 5
                           METHOD: _interior([[4.0, 2.3, 5.0], [0.5, 2.0, np.nan]])},
             "confidences": confidences, "per_frame": per_frame}
    if surfaces:
        scene["surfaces"] = tile_surfaces
    return scene


def _scenes(**kwargs) -> list[dict]:
    ref_conf = _interior([[0.9, 0.8, 0.1], [0.7, 0.5, 0.6]])  # the reference's gross tile is its least sure
    return [_scene({METHOD: {"seconds": 1.0, "tile_passes": 100}}, {REF: ref_conf, METHOD: ref_conf}, **kwargs),
            _scene({METHOD: {"seconds": 3.0}, REF: {}}, {REF: ref_conf}, **kwargs)]


def test_summarise_counts_by_hand():
    stats, curves = report.summarise(_scenes(), [REF, METHOD], reference=REF)
    m, r = stats[METHOD]["flat"], stats[REF]["flat"]
    assert m["tiles"] == 12 and np.isclose(m["coverage"], 10 / 12)
    assert np.isclose(m["gross"], 6 / 10) and np.isclose(m["gross_either"], 4 / 10)
    assert np.isclose(m["rmse_inliers"], np.sqrt((0.09 + 0.0) / 2))  # its own inliers: 2.3 and 2.0
    assert m["new_gross"] == 4 and np.isclose(m["new_gross_share"], 4 / 8)  # tiles 0 and 3 of each scene
    assert r["new_gross"] == 0 and np.isclose(r["gross"], 2 / 10) and np.isclose(r["gross_either"], 2 / 10)
    # the method has confidences in one scene only: none; the reference's 10 finite tiles by confidence end
    # with its two gross ones (0.1): 90 % keeps 9 (one gross), 75 % keeps 8 (none)
    assert m["confidence_ranking"] is None
    assert [(x["tiles"], x["gross"], x["gross_either"]) for x in r["confidence_ranking"]] == [(9, 1 / 9, 1 / 9),
                                                                                               (8, 0.0, 0.0)]
    assert stats[METHOD]["all"]["gross"] == m["gross"] and np.isnan(stats[METHOD]["edge"]["gross"])
    assert sum(b["tiles"] for b in curves[METHOD]) == 12 and "gross_either" in curves[METHOD][0]
    stats, _ = report.summarise(_scenes()[:1] + _scenes(surfaces=False)[1:], [REF, METHOD])
    assert "gross_either" not in stats[METHOD]["all"] and "new_gross" not in stats[METHOD]["all"]


def test_per_frame_means_over_the_scenes_that_report():
    assert report.per_frame(_scenes(), [REF, METHOD]) == {METHOD: {"seconds": 2.0, "tile_passes": 100.0}}


def test_table_columns_and_blanks():
    scenes = _scenes()
    stats, _ = report.summarise(scenes, [REF, METHOD], reference=REF)
    lines = report.table(stats, "title", REF, report.per_frame(scenes, [REF, METHOD]))
    assert lines[0] == "title" and max(map(len, lines)) < 200
    head = lines[next(i for i, line in enumerate(lines) if set(line) == {"-"}) - 1]
    for column in ("gross", "either", "rmse-in", "rmse-ref", "x ref", "new-gross", "cover", "right", "top 90%", "top 75%",
                   "passes", "s/frame"):
        assert column in head
    block = lines.index("all (12 tiles)")
    ref_row, method_row = lines[block + 1], lines[block + 2]
    assert ref_row.split() == [REF, "|", "20.0%", "20.0%", "0.112", "0.112", "1.00x", "(ref)", "83%", "67%", "|",
                               "11.1%/11.1%", "0.0%/0.0%", "|"]  # no costs handed in: blank
    assert method_row.split() == [METHOD, "|", "60.0%", "40.0%", "0.212", "1.454", "13.00x", "4", "50.0%", "83%", "33%", "|",
                                  "|", "100", "2.00"]  # no confidences: blank
    assert lines[-1] == method_row
    stats, _ = report.summarise(scenes, [REF, METHOD])  # no reference: its columns blank
    method_row = report.table(stats, "title", REF)[-1]
    assert method_row.split() == [METHOD, "|", "60.0%", "40.0%", "0.212", "83%", "33%", "|", "|"]
