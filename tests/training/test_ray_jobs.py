"""Many scenes on Ray (tpnet_gpu/training/ray_jobs.py, tpnet_gpu/cli/ray.py; issue 18): on a local Ray of 2 workers,
``tpnet process --ray`` writes for every scene folder exactly the files that ``tpnet process`` writes for it alone
(oracle: the serial command run here, scene by scene, in its own output folder; compared byte for byte, every
TIFF's array bit for bit with NaN in the same places), and ``tpnet dataset --ray`` the same chunk arrays and
manifest as the serial build; a run skips outputs finished before it (file identity unchanged). Without Ray the
options end in one line naming the extra. The Ray tests skip with a reason when the ``ray`` extra is missing."""

import json
import shutil
import sys

import numpy as np
import pytest
import tifffile

from tpnet_gpu.training import dataset
from tpnet_gpu.training import ray_jobs
from tpnet_gpu.cli import main
from tpnet_gpu.training.dataset import DatasetSpec

# two scenes of one size (an actor reuses its pipeline) and one of another (a second pipeline); "d" is finished
# before the Ray run (the resume: kept as it is, not processed again)
SCENES = {"a": (64, 48, 1), "b": (64, 48, 2), "c": (96, 64, 3), "d": (64, 48, 4)}  # name: width, height, seed
SPEC = DatasetSpec(scenes=3, width=64, height=48, test_fraction=0.34, seed=7, supersample=1)


def test_ray_options_without_the_extra_or_without_ray_end_in_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ModuleNotFoundError
    with pytest.raises(ModuleNotFoundError, match=r"--ray needs the 'ray' package: pip install 'tpnet-gpu\[ray\]'"):
        ray_jobs.import_ray()
    for argv in (["process", "--ray", str(tmp_path), "--out", str(tmp_path / "o")],
                 ["dataset", str(tmp_path / "d"), "--ray", "--scenes", "1"]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"tpnet {argv[0]}: error: --ray needs the 'ray' package") and err.count("\n") == 1
    assert main(["process", str(tmp_path), "--workers", "2", "--out", str(tmp_path / "o")]) == 2
    assert "--workers: expected only with --ray, got 2" in capsys.readouterr().err
    assert main(["dataset", str(tmp_path / "d"), "--address", "h:1"]) == 2
    assert "--address: expected only with --ray, got h:1" in capsys.readouterr().err
    assert not (tmp_path / "o").exists() and not (tmp_path / "d").exists()


def test_plan_skips_finished_scenes_and_refuses_bad_inputs(tmp_path):
    # no Ray needed: which scenes a run does (a present, non-empty output folder is a finished scene)
    from tpnet_gpu.cli import build_parser
    from tpnet_gpu.cli.ray import _plan

    for name in ("a", "b", "c"):
        (tmp_path / "in" / name).mkdir(parents=True)
    (tmp_path / "out" / "a").mkdir(parents=True)
    (tmp_path / "out" / "a" / "disparity.tif").write_bytes(b"done")
    (tmp_path / "out" / "b").mkdir()  # an empty folder is not a finished scene
    inputs = [str(tmp_path / "in" / n) for n in ("a", "b", "c")]
    args = build_parser().parse_args(["process", "--ray", *inputs, "--out", str(tmp_path / "out")])
    todo, done = _plan(args)
    assert done == ["a"] and [t["out"] for t in todo] == [str(tmp_path / "out" / n) for n in ("b", "c")]
    args.overwrite = True
    assert len(_plan(args)[0]) == 3
    args.inputs = [*inputs, str(tmp_path / "out" / "a" / "disparity.tif")]
    with pytest.raises(ValueError, match=r"inputs: expected scene folders with --ray, got .*disparity.tif"):
        _plan(args)
    (tmp_path / "other" / "a").mkdir(parents=True)
    args.inputs = [*inputs, str(tmp_path / "other" / "a")]
    with pytest.raises(ValueError, match="inputs: expected scene folders of different names .* got a more than once"):
        _plan(args)
    args.inputs, args.out = inputs, str(tmp_path / "in" / "a" / "out")
    with pytest.raises(ValueError, match="--out: expected a folder apart from the inputs"):
        _plan(args)


@pytest.fixture(scope="module")
def local_ray():
    pytest.importorskip("ray", reason="the ray extra is not installed (pip install 'tpnet-gpu[ray]')")
    pytest.importorskip("ray.data", reason="the ray extra is not installed (pip install 'tpnet-gpu[ray]')")
    with ray_jobs.session(ray_jobs.RayOptions(workers=2)) as (workers, gpu):  # one start for the module's tests
        assert workers == 2 and not gpu
        yield


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    root = tmp_path_factory.mktemp("scenes")
    for name, (width, height, seed) in SCENES.items():
        assert main(["render", str(root / name), "--width", str(width), "--height", str(height), "--seed", str(seed),
                     "--supersample", "1"]) == 0
    return root


def _same_files(first, second):
    names = sorted(p.name for p in first.iterdir())
    assert names == sorted(p.name for p in second.iterdir()) and "disparity.tif" in names
    for name in names:
        if name.endswith(".tif"):
            a, b = tifffile.imread(first / name), tifffile.imread(second / name)
            assert a.dtype == b.dtype and a.shape == b.shape, name
            np.testing.assert_array_equal(a.view(np.uint32), b.view(np.uint32), err_msg=name)  # bits, NaN too
        assert (first / name).read_bytes() == (second / name).read_bytes(), name


@pytest.mark.slow
def test_process_on_two_ray_workers_equals_the_serial_runs_and_resumes(local_ray, scenes, tmp_path, capsys):
    folders = [str(scenes / name) for name in SCENES]
    for folder in folders:  # the oracle: each scene alone through the serial command
        assert main(["process", folder, "--out", str(tmp_path / "serial" / folder[-1]), "--device", "cpu"]) == 0
    # resume in the same Ray run (one pool start, not two): "d" is finished before it, a present output folder
    out = tmp_path / "ray"
    shutil.copytree(tmp_path / "serial" / "d", out / "d")
    kept = {p.name: p.stat().st_ino for p in (out / "d").iterdir()}
    capsys.readouterr()
    assert main(["process", "--ray", "--workers", "2", *folders, "--out", str(out), "--device", "cpu"]) == 0
    assert "on Ray: 3 scene folders processed, 1 done before (skipped), 0 failed" in capsys.readouterr().out
    for name in SCENES:
        _same_files(tmp_path / "serial" / name, out / name)
    assert {p.name: p.stat().st_ino for p in (out / "d").iterdir()} == kept  # kept as it was, not rewritten
    assert np.isfinite(tifffile.imread(out / "c" / "disparity.tif")).mean() > 0.5  # a real result, not all NaN


@pytest.mark.slow
def test_dataset_on_two_ray_workers_equals_the_serial_build_and_resumes(local_ray, tmp_path):
    dataset.build(tmp_path / "serial", SPEC, device="cpu", progress=False)
    dataset.build(tmp_path / "ray", SPEC, device="cpu", progress=False, chunks=ray_jobs.chunk_builder(ray_jobs.RayOptions(workers=2)))
    assert (json.loads((tmp_path / "ray" / "manifest.json").read_text())
            == json.loads((tmp_path / "serial" / "manifest.json").read_text()))
    for index in range(SPEC.scenes):
        path = dataset.chunk_path(tmp_path / "serial", index)
        with np.load(path) as serial, np.load(tmp_path / "ray" / path.name) as ray:
            assert sorted(serial.files) == sorted(ray.files)
            for key in serial.files:
                np.testing.assert_array_equal(serial[key], ray[key], err_msg=f"{path.name}: {key}")
                assert serial[key].dtype == ray[key].dtype
    # resume: every chunk present, nothing rebuilt (no worker is even started)
    inodes = [p.stat().st_ino for p in sorted((tmp_path / "ray").glob("scene_*.npz"))]
    assert ray_jobs.build_chunks(tmp_path / "ray", SPEC, [], ray_jobs.RayOptions(workers=2)) == []
    dataset.build(tmp_path / "ray", SPEC, device="cpu", progress=False, chunks=ray_jobs.chunk_builder(ray_jobs.RayOptions(workers=2)))
    assert [p.stat().st_ino for p in sorted((tmp_path / "ray").glob("scene_*.npz"))] == inodes
    assert sorted(p.name for p in (tmp_path / "ray").iterdir()) == ["manifest.json"] + [
        f"scene_{i:04d}.npz" for i in range(SPEC.scenes)]  # no temporary file left
