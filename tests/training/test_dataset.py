"""Data set builder (tpnet_gpu/training/dataset.py): chunks, split by scene, targets, and the layers equal to what the
tile processor gives for the stored targets (oracle: a fresh TileProcessor run on the re-rendered scene)."""

import json

import numpy as np
import pytest

from tpnet_gpu.training import dataset
from tpnet_gpu.training.dataset import DatasetSpec

SPEC = DatasetSpec(scenes=3, width=64, height=48, test_fraction=0.34, seed=4, supersample=1)


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    folder = tmp_path_factory.mktemp("ds")
    dataset.build(folder, SPEC, device="cpu", progress=False)
    return folder


def test_manifest_and_split(built):
    manifest = json.loads((built / "manifest.json").read_text())
    splits = [c["split"] for c in manifest["chunks"]]
    assert splits.count("test") == 1 and splits.count("train") == 2
    train, test = dataset.load(built, "train"), dataset.load(built, "test")
    assert len(train) == 2 and len(test) == 1
    assert {int(c["scene"]) for c in train}.isdisjoint({int(c["scene"]) for c in test})


def test_chunk_contents(built):
    chunk = dataset.load(built, "train")[0]
    assert chunk["layers_random"].shape == (6, 8, 4, 9, 9) and chunk["layers_random"].dtype == np.float16
    assert chunk["layers_heuristic"].shape == (6, 8, 4, 9, 9)
    offset = chunk["target_random"] - chunk["gt_disparity"]
    assert np.all(np.abs(offset) <= SPEC.random_offset + 1e-5) and offset.std() > 0.3  # uniform +-2 px
    assert np.isfinite(chunk["target_heuristic"]).all()
    assert np.isfinite(chunk["layers_heuristic"].astype(np.float32)).all()
    assert chunk["gt_confidence"].min() >= 0 and chunk["gt_confidence"].max() <= 1
    low, high = SPEC.near_offset
    for i in range(SPEC.near_draws):  # random sign, |offset| log-uniform in near_offset (float32 rounding)
        offset = (chunk[f"target_near{i}"].astype(np.float64) - chunk["gt_disparity"]).ravel()
        assert np.all(np.abs(offset) >= low * 0.99) and np.all(np.abs(offset) <= high * 1.01)
        assert (offset > 0).any() and (offset < 0).any()
        assert np.median(np.abs(offset)) < 0.15  # log-uniform: median sqrt(low * high) = 0.05, not 0.25


def test_build_resumes_and_rebuilds_identically(built, tmp_path):
    first = dataset.load(built, "test")[0]
    from tpnet_gpu.disparity import DisparityEngine
    from tpnet_gpu.net.layers import NetworkLayers

    engine = DisparityEngine(SPEC.height, SPEC.width, device="cpu")
    layers = NetworkLayers(engine.rig.offsets, engine.tp.pairs, "cpu")
    again = dataset.build_scene(int(first["scene"]), SPEC, engine, engine.tp, layers)
    np.testing.assert_array_equal(again["gt_disparity"], first["gt_disparity"])
    for variant in SPEC.variants():  # deterministic per seed; the layers are the processor's at the targets
        np.testing.assert_array_equal(again[f"layers_{variant}"], first[f"layers_{variant}"])
        np.testing.assert_array_equal(again[f"target_{variant}"], first[f"target_{variant}"])


def test_stored_raws_re_measure_to_the_stored_layers(built):
    """The chunk's raw frames are the scene's (oracle: re-measuring them at the stored targets gives the stored
    layers bit for bit), and ``measured`` marks the engine's tiles (unmeasured ones are ground truth + <= 2 px)."""
    chunk = dataset.load(built, "train")[0]
    assert chunk["raws"].shape == (4, SPEC.height, SPEC.width) and chunk["raws"].dtype == np.uint16
    assert chunk["gt_surfaces"].shape[:2] == chunk["gt_disparity"].shape
    measurers = dataset.measurers(SPEC, "cpu")
    layers = dataset.remeasure(chunk, chunk["target_near0"], *measurers)
    np.testing.assert_array_equal(layers, chunk["layers_near0"])
    measured = chunk["measured"]
    assert measured.dtype == bool and measured.any()
    offset = np.abs(chunk["target_heuristic"] - chunk["gt_disparity"])[~measured]
    assert np.all(offset <= SPEC.random_offset + 1e-5)


def test_network_layers_are_green_only_as_the_baseline():
    assert SPEC.correlation().colour_weights == (0.0, 0.0, 1.0)
    assert SPEC.variants() == ("heuristic", "random", "near0", "near1")


def test_old_data_set_version_is_refused(built, tmp_path):
    manifest = json.loads((built / "manifest.json").read_text())
    manifest["version"] = 1
    (tmp_path / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(ValueError, match="expected data set version 4, got 1"):
        dataset.load(tmp_path, "train")


def test_bad_split_and_missing_manifest(tmp_path):
    with pytest.raises(ValueError, match="split: expected 'train' or 'test', got 'val'"):
        dataset.load(tmp_path, "val")
    with pytest.raises(FileNotFoundError, match="no data set manifest"):
        dataset.load(tmp_path, "train")


@pytest.fixture(scope="module")
def binocular(tmp_path_factory):
    """A two-scene data set of the shipped binocular rig, built through the CLI (``tpnet dataset --rig``)."""
    from tpnet_gpu import cli  # noqa: PLC0415

    folder = tmp_path_factory.mktemp("bino")
    assert cli.main(["dataset", str(folder), "--rig", "binocular", "--scenes", "2", "--width", "64", "--height", "48",
                     "--supersample", "1", "--test-fraction", "0.5", "--seed", "4", "--device", "cpu"]) == 0
    return folder


def test_dataset_rig_goes_in_the_manifest(binocular):
    from tpnet_gpu.io import rigfile  # noqa: PLC0415

    manifest = json.loads((binocular / "manifest.json").read_text())
    assert manifest["lags"] == [[1.0, 0.0]]
    assert manifest["spec"]["rig"] == rigfile.rig_to_dict(rigfile.load("binocular"))
    rig = dataset.spec_rig(DatasetSpec(**manifest["spec"]))
    assert (rig.width, rig.height, rig.offsets) == (64, 48, ((-0.5, 0.0), (0.5, 0.0)))  # ideal: the spec's size
    assert dataset.spec_rig(SPEC).offsets == ((-0.5, -0.5), (0.5, -0.5), (-0.5, 0.5), (0.5, 0.5))  # None: the quad


def test_binocular_layers_are_the_pairs_correlation(binocular):
    """Oracle: a fresh tile processor of the two cameras on the stored raw frames, scaled as the engine scales
    them: the one layer is the centre 9x9 of the pair's correlation at the stored targets (float16)."""
    from tpnet_gpu.disparity.engine import REFERENCE_LEVEL  # noqa: PLC0415
    from tpnet_gpu.processor import TileProcessor  # noqa: PLC0415

    chunk = dataset.load(binocular, "train")[0]
    assert chunk["raws"].shape == (2, 48, 64) and chunk["layers_random"].shape == (6, 8, 1, 9, 9)
    frames = chunk["raws"].astype(np.float32) - chunk["black_level"]
    frames = frames * np.float32(REFERENCE_LEVEL / np.abs(frames).mean())
    tp = TileProcessor(48, 64, camera_offsets=((-0.5, 0.0), (0.5, 0.0)), pairs=((0, 1),), config=SPEC.correlation())
    corr = tp.process(frames, chunk["target_random"]).corr.numpy()
    want = corr[:, 0, 3:12, 3:12].reshape(6, 8, 1, 9, 9).astype(np.float16)
    np.testing.assert_allclose(chunk["layers_random"].astype(np.float32), want.astype(np.float32), rtol=2e-3,
                               atol=2e-4)  # the engine's scale is a float32 device scalar: float16 rounding apart


def test_calibrated_rig_of_another_size_is_refused():
    from tpnet_gpu.io import rigfile  # noqa: PLC0415

    rig = rigfile.rig_to_dict(rigfile.load("binocular"))
    rig["distortion"] = [0.01] + [0.0] * 6
    with pytest.raises(ValueError, match="spec.rig: expected a calibrated rig of the data set's size 64x48, "
                                         "got 2592x1936"):
        dataset.spec_rig(DatasetSpec(width=64, height=48, rig=rig))


def test_no_scenes_is_a_one_line_error_and_no_folder(tmp_path, capsys):
    # Oracle: the CLI contract (one line `tpnet dataset: error: ...` naming the option, exit 2, nothing written);
    # before, `--scenes 0` exited 0 with an empty data set.
    from tpnet_gpu import cli  # noqa: PLC0415

    for scenes in ("0", "-3"):
        assert cli.main(["dataset", str(tmp_path / "d"), "--scenes", scenes, "--width", "64", "--height", "48"]) == 2
        err = capsys.readouterr().err
        assert err == f"tpnet dataset: error: --scenes: expected at least 1 scene, got {scenes}\n"
    assert not (tmp_path / "d").exists()
    with pytest.raises(ValueError, match="scenes: expected an integer >= 1, got 0"):  # the library's spec
        DatasetSpec(scenes=0, width=64, height=48)


def test_mono_data_set_has_one_colour(tmp_path):
    """``tpnet dataset --mono``: one-colour frames and layers (the processors that made them read mono frames),
    correlation settings of one colour weight, and the spec in the manifest; a mono spec of three weights is
    refused naming the field."""
    from tpnet_gpu import cli  # noqa: PLC0415

    assert cli.main(["dataset", str(tmp_path), "--rig", "binocular", "--mono", "--scenes", "2", "--width", "64",
                     "--height", "48", "--supersample", "1", "--test-fraction", "0.5", "--seed", "4",
                     "--device", "cpu"]) == 0
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert manifest["spec"]["cfa"] is None and manifest["spec"]["colour_weights"] == [1.0]
    chunk = dataset.load(tmp_path, "train")[0]
    assert chunk["layers_random"].shape == (6, 8, 1, 9, 9)
    spec = DatasetSpec(**{k: tuple(v) if isinstance(v, list) else v for k, v in manifest["spec"].items()})
    assert spec.correlation().colour_weights == (1.0,)
    engine, processor, _ = dataset.measurers(spec, "cpu")
    assert engine.tp.colours == processor.colours == 1
    with pytest.raises(ValueError, match="colour_weights"):
        DatasetSpec(cfa=None)  # three colour weights for one colour


def test_photo_data_set_stores_8_bit_photographs(tmp_path, capsys):
    """``--mono --photo``: the stored frames are what an image pair gives (0..255, black level 0) and re-measure to
    the stored layers (oracle: ``remeasure`` from those frames equals the build's layers); --photo without
    --mono, or a Bayer spec with photo, is refused naming the option."""
    from tpnet_gpu import cli  # noqa: PLC0415

    assert cli.main(["dataset", str(tmp_path / "p"), "--rig", "binocular", "--mono", "--photo", "--scenes", "1",
                     "--width", "64", "--height", "48", "--supersample", "1", "--test-fraction", "0",
                     "--device", "cpu"]) == 0
    chunk = dataset.load(tmp_path / "p", "train")[0]
    assert chunk["black_level"] == 0 and chunk["raws"].max() <= 255 and chunk["raws"].max() > 100
    manifest = json.loads((tmp_path / "p" / "manifest.json").read_text())
    spec = DatasetSpec(**{k: tuple(v) if isinstance(v, list) else v for k, v in manifest["spec"].items()})
    assert spec.photo
    again = dataset.remeasure(chunk, chunk["target_random"], *dataset.measurers(spec, "cpu"))
    np.testing.assert_array_equal(again, chunk["layers_random"])
    assert cli.main(["dataset", str(tmp_path / "q"), "--photo", "--scenes", "1"]) == 2
    assert "--photo" in capsys.readouterr().err and not (tmp_path / "q").exists()
    with pytest.raises(ValueError, match="photo"):
        DatasetSpec(photo=True)


def test_a_scene_that_fails_leaves_no_temporary_chunk(tmp_path, monkeypatch):
    # issue 40 item 6 (the campaign's `dataset --supersample -1`): the failed scene's .tmp-*.npz stayed behind
    def failing(*args, **kwargs):
        raise ValueError("supersample: bad")

    monkeypatch.setattr(dataset, "build_scene", failing)
    with pytest.raises(ValueError, match="supersample: bad"):
        dataset.write_chunk(tmp_path, 0, SPEC, None, None, None)
    assert list(tmp_path.iterdir()) == []
