"""Every bench of tpnet_gpu.bench run end to end at a tiny size (as Warp's test suite runs its examples): its
``main(argv)`` returns the report, prints its table, logs progress to stderr and writes the same report as JSON;
``tpnet bench NAME`` reaches the same ``main``. Oracle: the report layout each bench documents (its keys), and for
the speed benches the agreement of the twins with the Warp processor (their own tolerance, 1e-4 of max |warp|).
The accuracy bench needs the optional ``bench`` extra (OpenCV) and skips without it."""

from __future__ import annotations

import importlib.util
import json
import pkgutil
import subprocess
import sys

import numpy as np
import pytest
import torch

import tpnet_gpu.bench
from tpnet_gpu import cli
from tpnet_gpu.bench import common
from tpnet_gpu.bench.accuracy import bench_network
from tpnet_gpu.bench.throughput import bench_throughput
from tpnet_gpu.bench.throughput import bench_tp
from tpnet_gpu.bench.throughput.throughput_report import ROWS

TINY = ["--height", "32", "--width", "48", "--repeat", "1", "--device", "cpu"]  # 4 x 6 tiles
PIPELINE = ["--pipeline-sizes", "64x48", "--pipeline-frames", "1", "--pipeline-backend", "warp"]  # 6 x 8 tiles
PIPELINE_ROW = {"size", "tiles", "backend", "process_ms", "fps", "stages_ms", "tile_passes", "tp_pass",
                "twin_tp_estimate_ms", "floor"}
SPEED_KEYS = {"frame", "timing", "stages", "device", "machine", "paper", "agreement"}
ACCURACY_KEYS = {"bench", "scenes", "width", "height", "seed", "machine", "stats", "per_frame", "rmse_by_spread",
                 "table"}
CLASSES = {"flat", "edge", "low_texture", "all"}
CLASS_STATS = {"tiles", "coverage", "right", "rmse", "median_abs", "gross", "gross_either", "rmse_inliers", "rmse_common",
               "new_gross", "new_gross_share", "confidence_ranking"}  # evaluation.error_stats + confidence_ranking


def _check_accuracy(report: dict, ranked: set) -> None:
    """Every method: the class statistics (with the reference's and the surfaces' keys), a confidence ranking
    for the ``ranked`` methods only, and its seconds per frame."""
    for method, stats in report["stats"].items():
        assert set(stats) == CLASSES and all(set(s) == CLASS_STATS for s in stats.values()), method
        assert (stats["all"]["confidence_ranking"] is not None) == (method in ranked), method
        assert report["per_frame"][method]["seconds"] > 0


@pytest.fixture(autouse=True)
def keep_torch_state():
    """The throughput bench seeds torch's RNG (and may set its thread count): restored for the other tests."""
    threads = torch.get_num_threads()
    with torch.random.fork_rng(devices=[]):
        yield
    torch.set_num_threads(threads)


def run_bench(module, argv, tmp_path, capsys) -> tuple[dict, str, str]:
    """``module.main(argv + --json)``: (returned report, stdout, stderr); the JSON file must hold the same report."""
    path = tmp_path / f"{module.__name__.rpartition('.')[2]}.json"
    report = module.main([*argv, "--json", str(path)])
    out, err = capsys.readouterr()
    assert isinstance(report, dict)
    assert json.loads(path.read_text()) == json.loads(json.dumps(report, default=float))
    return report, out, err


def test_bench_tp(tmp_path, capsys):
    report, out, err = run_bench(bench_tp, TINY, tmp_path, capsys)
    assert SPEED_KEYS | {"total", "warp_setup_ms", "warp_first_prepare_ms", "warp_process_ms"} <= set(report)
    assert [s["name"] for s in report["stages"]] == ["convert", "correlate", "texture"]
    assert report["frame"]["tiles"] == 24 and report["frame"]["width"] == 48 and report["frame"]["height"] == 32
    assert report["agreement"]["clt_max_rel_diff"] < 1e-4 and report["agreement"]["corr_max_rel_diff"] < 1e-4
    assert {"cpu_model", "numpy", "warp", "torch", "thread_env"} <= set(report["machine"])
    assert "stage" in out and "convert" in out and "paper:" in out
    assert "[bench_tp] wrote" in err  # progress through common.logger, on stderr


def _check_throughput(report: dict, columns: list[str]) -> None:
    assert SPEED_KEYS | {"columns", "graph_replay", "targets", "soak"} <= set(report)
    assert report["columns"] == columns
    assert [s["name"] for s in report["stages"]] == [name for name, _ in ROWS]
    for impl in columns[1:]:
        for name, stats in report["agreement"][impl].items():
            assert stats["max_rel_diff"] < 1e-4, (impl, name)
    assert report["agreement"]["network_split_vs_forward_frame_max_abs_diff"] < 1e-5
    assert set(report["floor"]["rows"]) == {"TP whole frame", "network whole frame", "TP+network whole frame"}


def _check_pipeline(section: dict, scene: str) -> None:
    (row,) = section["rows"]
    assert PIPELINE_ROW <= set(row) and row["size"] == {"width": 64, "height": 48} and row["scene"] == scene
    assert set(row["stages_ms"]) == set(section["stages"]) and row["tile_passes"] > 0
    assert row["tp_pass"]["corr_agreement"]["max_rel_diff"] < 1e-4  # the twin against the engine's processor
    assert row["floor"]["frame"]["floor_ms"] > row["floor"]["tp_pass"]["floor_ms"] > 0
    assert section["paper"]["tp_ms"] == 87.0
    # the peer in the same run (OpenCV is in the test extra) and this CPU's roofline for the TP pass
    assert row["sgbm"]["ms"]["median"] > 0 and row["sgbm_ratio"] == pytest.approx(
        row["process_ms"]["median"] / row["sgbm"]["ms"]["median"])
    roof = row["cpu_roofline"]
    assert roof["fp32_flops_per_s"] > 0 and 0 < roof["share_of_peak"] < 1


def test_bench_throughput_without_taichi(tmp_path, capsys):
    report, out, err = run_bench(bench_throughput, [*TINY, "--no-taichi", "--soak", "2", *PIPELINE], tmp_path,
                                 capsys)
    _check_throughput(report, ["warp", "numpy", "torch"])
    _check_pipeline(report["pipeline"], "demo")
    assert "Pipeline.process" in out and "paper 2592x1936" in out and "floor (NVIDIA H200" in out
    assert report["soak"]["frames"] == 2 and report["soak"]["size"] == {"width": 48, "height": 32}
    assert report["graph_replay"]["available"]
    assert "TP+network whole frame" in out and "[bench_throughput]" in err


def test_bench_throughput_pipeline_only(tmp_path, capsys):
    argv = ["--device", "cpu", "--pipeline-only", "--pipeline-scene", "random", *PIPELINE]
    report, out, _ = run_bench(bench_throughput, argv, tmp_path, capsys)
    assert set(report) == {"pipeline", "device", "machine"}
    _check_pipeline(report["pipeline"], "random")
    assert "convert" not in out and "64x48 floor" in out and "CPU roofline 64x48" in out and "ours/SGBM" in out


@pytest.mark.slow
def test_bench_throughput_taichi_worker(tmp_path, capsys):
    # One Taichi column: a worker process started as `python -m tpnet_gpu.bench.throughput.bench_throughput`.
    argv = [*TINY, "--taichi-threads", "1", "--pipeline-sizes", ""]
    report, out, _ = run_bench(bench_throughput, argv, tmp_path, capsys)
    _check_throughput(report, ["warp", "numpy", "torch", "taichi-1t"])
    assert report["timing"]["taichi_setup"]["taichi-1t"]["threads"] == 1
    assert "taichi-1t ms" in out


@pytest.mark.slow
def test_bench_accuracy(tmp_path, capsys):
    pytest.importorskip("cv2", reason="bench_accuracy's peers need OpenCV (the optional 'bench' extra)")
    from tpnet_gpu.bench.accuracy import bench_accuracy

    png = tmp_path / "accuracy.png" if importlib.util.find_spec("matplotlib") else None
    # 128x64: SGBM needs an image wider than its disparity range; one re-centring pass keeps the peers short.
    argv = ["--scenes", "1", "--height", "64", "--width", "128", "--peer-passes", "1", "--png", str(png or "")]
    report, out, err = run_bench(bench_accuracy, argv, tmp_path, capsys)
    assert ACCURACY_KEYS | {"peer_passes", "optics", "sensor"} <= set(report)
    assert list(report["stats"]) == ["baseline (G phase correlation)", "baseline (as-coded colour weights)",
                                     "opencv-StereoSGBM", "opencv-phaseCorrelate", "skimage-phase_cross_correlation"]
    _check_accuracy(report, {"baseline (G phase correlation)", "baseline (as-coded colour weights)"})
    assert report["table"][0] in out and "[bench_accuracy]" in err
    assert png is None or png.stat().st_size > 0


def test_bench_network(tmp_path, capsys):
    png = tmp_path / "network.png" if importlib.util.find_spec("matplotlib") else None
    argv = ["--scenes", "1", "--passes", "1", "--height", "64", "--width", "64", "--png", str(png or "")]
    report, out, err = run_bench(bench_network, argv, tmp_path, capsys)
    assert ACCURACY_KEYS | {"passes"} <= set(report)
    assert list(report["stats"]) == ["old sweep + LMA", "engine", "engine (LMA)", "TPNET (1 pass, no context)",
                                     "TPNET (1 pass)"]
    _check_accuracy(report, {"old sweep + LMA", "engine", "engine (LMA)"})
    passes = report["per_frame"]
    assert passes["old sweep + LMA"]["tile_passes"] >= 8 and passes["engine"]["tile_passes"] > 0  # budget: engine tests
    assert report["table"][0] in out and "[bench_network]" in err
    assert png is None or png.stat().st_size > 0


def test_bench_network_binocular(tmp_path, capsys):
    """``--rig binocular``: no old loop (quad only), the engine with the LMA (its pair in the quad's pair-0 slot);
    TPNET with one-layer weights, against the engine."""
    from tpnet_gpu.net.model import TPNet  # noqa: PLC0415

    weights = tmp_path / "bino.pt"
    torch.save(TPNet(layers=1).state_dict(), weights)
    weights.with_suffix(".json").write_text(json.dumps({"lags": [[1.0, 0.0]]}))
    argv = ["--scenes", "1", "--passes", "1", "--height", "64", "--width", "64", "--png", "", "--rig", "binocular",
            "--weights", str(weights)]
    report, out, err = run_bench(bench_network, argv, tmp_path, capsys)
    assert list(report["stats"]) == ["engine", "engine (LMA)", "TPNET (1 pass, no context)", "TPNET (1 pass)"]
    assert report["rig"] == "binocular"
    _check_accuracy(report, {"engine", "engine (LMA)"})
    assert "rig binocular (2 cameras)" in report["table"][0]
    torch.save(TPNet().state_dict(), tmp_path / "quad.pt")  # no recipe: the quad's lags
    with pytest.raises(SystemExit):  # quad weights for a binocular rig: refused by the parser
        bench_network.main([*argv[:-1], str(tmp_path / "quad.pt")])
    assert "were trained for layer lags ((1.0, 0.0), (0.0, 1.0)" in capsys.readouterr().err


def test_bench_network_mono(tmp_path, capsys):
    """``--mono``: mono frames and one-colour weights (the recipe's colour weights say so); Bayer weights are
    refused by the parser naming --weights."""
    from tpnet_gpu.net.model import TPNet  # noqa: PLC0415

    weights = tmp_path / "mono.pt"
    torch.save(TPNet(layers=1).state_dict(), weights)
    spec = {"colour_weights": [1.0], "fat_zero": 1e4, "cfa": None}
    weights.with_suffix(".json").write_text(json.dumps({"lags": [[1.0, 0.0]], "dataset_spec": spec}))
    argv = ["--scenes", "1", "--passes", "1", "--height", "64", "--width", "64", "--png", "", "--rig", "binocular",
            "--mono", "--weights", str(weights)]
    report, _, _ = run_bench(bench_network, argv, tmp_path, capsys)
    assert "mono" in report["table"][0] and report["mono"] is True
    _check_accuracy(report, {"engine", "engine (LMA)"})
    bayer = tmp_path / "bayer.pt"
    torch.save(TPNet(layers=1).state_dict(), bayer)
    bayer.with_suffix(".json").write_text(json.dumps({"lags": [[1.0, 0.0]], "dataset_spec": {**spec, "colour_weights":
                                                                                           [0.0, 0.0, 1.0]}}))
    with pytest.raises(SystemExit):
        bench_network.main([*argv[:-1], str(bayer)])
    assert "--weights" in capsys.readouterr().err


def test_bench_network_limits(tmp_path, capsys):
    from tpnet_gpu.bench.accuracy import bench_network_limits as limits

    argv = ["--scenes", "1", "--passes", "2", "--height", "64", "--width", "96"]
    report, out, err = run_bench(limits, argv, tmp_path, capsys)
    starts = report["starts"]
    assert len(starts) == len(limits.FRACTIONS) + len(limits.NOISE_PX)
    engine_start = starts["gt + 1 (engine - gt)"]["all"]
    truth_start = starts["gt + 0 (engine - gt)"]["all"]
    assert engine_start["tiles"] == truth_start["tiles"] > 0
    assert truth_start["rmse_start"] == 0.0 and engine_start["rmse_start"] > 0  # physical: the truth has no error
    assert report["passes_rmse"]["gt"]["all"][0] == 0.0 and len(report["passes_rmse"]["engine"]["all"]) == 3
    assert len(report["noise_free"]["all"]) == 4
    for rows in report["budget"].values():
        assert sum(r["sse_share"] for r in rows) == pytest.approx(1.0) or all(r["sse_share"] == 0 for r in rows)
    assert report["table"][0] in out and "[bench_network_limits]" in err


def test_bench_network_context(tmp_path, capsys):
    from tpnet_gpu.bench.accuracy import bench_network_context as context
    from tpnet_gpu.net.context import context_step

    argv = ["--scenes", "2", "--check-from", "1", "--height", "64", "--width", "96"]
    report, out, err = run_bench(context, argv, tmp_path, capsys)
    assert list(report["stats"]) == ["tuning", "check"]
    for per in report["stats"].values():
        assert {"engine", "TPNET, 1 pass", "TPNET + shipped step, 1 pass", "engine + shipped step"} <= set(per)
        assert all(set(stats) == {"flat", "edge", "all"} for stats in per.values())
    assert report["table"][0] in out and "[bench_network_context]" in err
    # the bench's family of steps at the shipped settings is the shipped step (a grid with NaN holes, two surfaces)
    grid = torch.from_numpy(np.random.default_rng(0).normal(5.0, 0.3, (9, 11)).astype(np.float32))
    grid[2, 3], grid[:, 7:] = float("nan"), grid[:, 7:] + 3.0
    strength = torch.rand(9, 11, generator=torch.Generator().manual_seed(0))
    torch.testing.assert_close(context.variant(grid, strength), context_step(grid, strength), equal_nan=True)


def test_bench_fuzz(tmp_path, capsys):
    # A short campaign in its child process: its counts add up (each case has at least 4 tile tasks) and the
    # oracles hold (the same ones as tests/fuzz).
    from tpnet_gpu.bench.fuzz import bench_fuzz

    report, out, err = run_bench(bench_fuzz, ["--examples", "12", "--soak", "101", "--pipeline", "2", "--raw", "100",
                                              "--cli", "2"], tmp_path, capsys)
    assert report["crashed"] is False and report["cases"] == 12
    assert report["tile_tasks_per_backend"] >= 4 * 12 and report["failures"] == {}
    families = report["families"]
    assert [families[name]["cases"] for name in ("pipeline", "raw", "cli")] == [2, 100, 2]
    assert all(family["failures"] == {} for family in families.values())
    soak = report["soak"]  # frames 49 and 99 are bad, the other 99 good (3 distinct frames, each equal to its first)
    assert soak["bad frames given a FrameError"] == 2 and soak["good frames equal to their first"] == 99
    assert report["table"][0] in out


def test_every_bench_module_is_a_cli_choice():
    modules = {m.name.removeprefix("tpnet_gpu.bench.") for m in pkgutil.walk_packages(tpnet_gpu.bench.__path__,
                                                                                      "tpnet_gpu.bench.")
               if m.name.rpartition(".")[2].startswith("bench_")}
    assert modules == set(cli.bench.BENCHES.values())
    assert all(module.endswith(f"bench_{name}") for name, module in cli.bench.BENCHES.items())


def test_cli_runs_a_bench_by_import(tmp_path, capsys):
    json_path = tmp_path / "tp.json"
    assert cli.main(["bench", "tp", *TINY, "--json", str(json_path)]) == 0
    assert "convert" in capsys.readouterr().out
    assert set(json.loads(json_path.read_text())) >= SPEED_KEYS


def test_cli_bench_help_bad_options_and_unknown_name(capsys):
    assert cli.main(["bench", "tp", "--help"]) == 0
    assert "usage: tpnet bench tp" in capsys.readouterr().out
    assert cli.main(["bench", "tp", "--repeat", "0"]) == 2
    assert "tpnet bench tp: error: --repeat: expected at least 1" in capsys.readouterr().err
    with pytest.raises(SystemExit) as done:
        cli.main(["bench", "nope"])
    assert done.value.code == 2 and "invalid choice: 'nope'" in capsys.readouterr().err


def test_cli_missing_extra_is_one_line(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "cv2", None)  # import cv2 now fails as if OpenCV were not installed
    assert cli.main(["bench", "accuracy", "--scenes", "1"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.strip().splitlines()) == 1, err
    assert err.startswith("tpnet bench accuracy: error:") and common.EXTRA_HINT in err and "opencv" in err


def test_python_dash_m_runs_a_bench():
    done = subprocess.run([sys.executable, "-m", "tpnet_gpu.bench.throughput.bench_tp", "--repeat", "0"], capture_output=True,
                          text=True)
    assert done.returncode == 2 and "tpnet bench tp: error: --repeat: expected at least 1" in done.stderr


def test_bench_startup(tmp_path, capsys):
    # Warm rows only (--cache: the environment's kernel caches), one tiny frame, the Warp backend; two runs, as a
    # second run once failed (it wrote into the first one's output folder, which `tpnet process` refuses).
    from tpnet_gpu.bench.throughput import bench_startup
    from tpnet_gpu.runtime.taichi_setup import cache_dir

    argv = ["--sizes", "32x32", "--backends", "warp", "--repeat", "2", "--cache", str(cache_dir().parent)]
    report, out, err = run_bench(bench_startup, argv, tmp_path, capsys)
    assert {"bench", "sizes", "import_floor", "torch_floor", "machine", "cache", "table"} <= set(report)
    assert "torch floor: import torch" in out
    (entry,) = report["sizes"]
    assert (entry["width"], entry["height"]) == (32, 32) and list(entry["backends"]) == ["warp"]
    (row,) = entry["backends"]["warp"].values()
    assert list(entry["backends"]["warp"]) == ["warm"] and len(row["new_kernels"]) == 2
    assert 0 < row["reported_s"]["median"] < row["wall_s"]["median"]
    assert "32x32 warp warm" in out and "[bench_startup]" in err
    # --pair: a mono stereo pair of PNG images through `tpnet process LEFT RIGHT --max-disparity 64`; --figures:
    # a second warm row with the command's figures
    report, out, err = run_bench(bench_startup, [*argv[:-2], "--repeat", "1", "--pair", "--figures", "--cache",
                                                 argv[-1]], tmp_path, capsys)
    assert report["inputs"] == "mono pair" and "32x32 warp warm" in out and "32x32 warp warm, figures" in out
    assert list(report["sizes"][0]["backends"]["warp"]) == ["warm", "warm, figures"]


@pytest.mark.slow
def test_bench_ray(tmp_path, capsys):
    # One tiny scene, serial rows and a 1-worker Ray; every row's outputs must equal the first's (the bench checks).
    pytest.importorskip("ray", reason="the ray extra is not installed (pip install 'tpnet-gpu[ray]')")
    from tpnet_gpu.bench.throughput import bench_ray

    report, out, err = run_bench(bench_ray, ["--scenes", "1", "--size", "64x48", "--workers", "1"], tmp_path, capsys)
    assert {"bench", "scenes", "width", "height", "rows", "machine", "ray_start_stop_s", "table"} <= set(report)
    assert [r["mode"] for r in report["rows"]] == ["serial, a process per scene", "serial, one process",
                                                   "Ray, 1 worker"]
    assert all(r["wall_s"]["median"] > 0 and r["speedup"] > 0 for r in report["rows"])
    assert report["rows"][1]["speedup"] == 1.0  # the peer
    assert "outputs identical in every row" in out and "[bench_ray]" in err


@pytest.mark.parametrize("pair", [False, True], ids=["quad", "pair"])
def test_bench_video(tmp_path, capsys, pair):
    from tpnet_gpu.bench.accuracy import bench_video

    argv = ["--sequences", "1", "--frames", "2", "--width", "128", "--height", "96"] + (["--pair"] if pair else [])
    report, out, err = run_bench(bench_video, argv, tmp_path, capsys)
    assert report["rig"] == ("binocular, mono" if pair else "quad, Bayer")
    assert report["per_pixel"] is pair  # a pair is checked per pixel, as `tpnet process LEFT_DIR RIGHT_DIR` does
    assert set(report["summary"]) == {"every frame searched", "following the frame before"}
    assert all(s["frames"] == 1 for s in report["summary"].values())
    followed, searched = (report["summary"][k]["passes"] for k in ("following the frame before",
                                                                    "every frame searched"))
    assert 1.0 <= followed < searched  # the followed frame reads every tile once, the searched one sweeps
    assert report["table"][0] in out and "[video]" in err
