"""Files that hold weights or training state are never unpickled (issue 40): every door that reads one -
``--weights`` (process, demo, export), ``train --init``, ``train --checkpoint`` - reads tensors and plain data
only, and a crafted, truncated or foreign file is one ``ValueError`` line naming the option and the file.
Oracles: a pickle whose loading would create a marker file (it must not appear), a truncated copy of real
weights, and the CLI's one-line contract."""

import os
import pickle

import pytest
import torch

from tests.net.test_train import data  # noqa: F401 - the tiny rendered data set (a module fixture)
from tpnet_gpu.cli import main
from tpnet_gpu.net import infer
from tpnet_gpu.net.train import TrainConfig, train


class _Payload:
    """Unpickling this runs ``os.mkdir(marker)``: what a crafted file would do with any command."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return os.mkdir, (self.marker,)


@pytest.fixture
def crafted(tmp_path):
    marker = tmp_path / "pwned"
    path = tmp_path / "crafted.pt"
    torch.save({"model": _Payload(marker)}, path, pickle_protocol=pickle.DEFAULT_PROTOCOL)
    return path, marker


@pytest.fixture
def truncated(tmp_path):
    path = tmp_path / "truncated.pt"
    path.write_bytes(infer.DEFAULT_WEIGHTS.read_bytes()[:5000])
    return path


def test_read_tensors_refuses_a_pickle_without_running_it(crafted, truncated):
    path, marker = crafted
    for bad in (path, truncated):
        with pytest.raises(ValueError, match=rf"^checkpoint: {bad} is not a file of a training checkpoint \("):
            infer.read_tensors(bad, "checkpoint", "a training checkpoint")
    assert not marker.exists()
    assert set(infer.read_tensors(infer.DEFAULT_WEIGHTS, "weights", "TPNET weights")) >= {"stage1.0.weight"}


def test_train_checkpoint_and_init_are_read_as_tensors_only(data, crafted, truncated, tmp_path):  # noqa: F811
    path, marker = crafted
    config = TrainConfig(epochs=1, batch=2)
    for bad in (path, truncated):
        with pytest.raises(ValueError, match=r"^checkpoint: .* is not a file of a training checkpoint"):
            train(data, tmp_path / "o.pt", config, checkpoint=bad, progress=False, log=lambda m: None)
        with pytest.raises(ValueError, match=r"^init: .* is not a file of TPNET weights"):
            train(data, tmp_path / "o.pt", TrainConfig(epochs=1, batch=2, init=str(bad)), progress=False,
                  log=lambda m: None)
    assert not marker.exists() and not (tmp_path / "o.pt").exists()


def test_cli_weights_doors_say_one_line(crafted, truncated, tmp_path, capsys):
    path, marker = crafted
    for bad in (path, truncated):
        assert main(["export", str(tmp_path / "n.onnx"), "--weights", str(bad)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"tpnet export: error: weights: {bad} is not a file of TPNET"), err
        assert main(["demo", "--out", str(tmp_path / "d"), "--width", "64", "--height", "48", "--no-figures",
                     "--weights", str(bad)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "weights: " in err[0] and str(bad) in err[0], err
    assert not marker.exists() and not (tmp_path / "d").exists()


@pytest.fixture
def nan_weights(tmp_path):
    """The shipped weights with one NaN (and their recipe beside them): before, `demo` reported all-NaN
    disparities and `export` wrote them to ONNX, exit 0."""
    state = infer.read_tensors(infer.DEFAULT_WEIGHTS, "weights", "TPNET weights")
    state["stage1.0.weight"][0, 0] = float("nan")
    path = tmp_path / "nan.pt"
    torch.save(state, path)
    path.with_suffix(".json").write_bytes(infer.DEFAULT_WEIGHTS.with_suffix(".json").read_bytes())
    return path


def test_nan_weights_are_refused_at_every_door(nan_weights, data, tmp_path, capsys):  # noqa: F811
    expected = f"weights: {nan_weights} holds NaN or infinite numbers (tensor 'stage1.0.weight')"
    for args in (["export", str(tmp_path / "n.onnx"), "--weights", str(nan_weights)],
                 ["demo", "--out", str(tmp_path / "d"), "--width", "64", "--height", "48", "--no-figures",
                  "--weights", str(nan_weights)]):
        assert main(args) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and expected in err[0], err
    with pytest.raises(ValueError, match=r"^init: .* holds NaN or infinite numbers"):
        train(data, tmp_path / "o.pt", TrainConfig(epochs=1, batch=2, init=str(nan_weights)), progress=False,
              log=lambda m: None)
    assert not (tmp_path / "n.onnx").exists() and not (tmp_path / "d").exists() and not (tmp_path / "o.pt").exists()


@pytest.mark.parametrize("text, field", [
    ("[1, 2]", "the file: expected a JSON object, got list"),
    ('{"lags": 5}', "lags: expected a list of [x, y] pairs, got 5"),
    ('{"lags": null}', "lags: expected a list of [x, y] pairs, got None"),
    ('{"lags": [[1, "a"]]}', "lags: expected a list of [x, y] pairs"),
    ('{"dataset_spec": [1]}', "dataset_spec: expected an object"),
    ('{"dataset_spec": {"colour_weights": "x"}}', "dataset_spec.colour_weights: expected a list of numbers"),
    ('{"dataset_spec": {"fat_zero": NaN}}', "dataset_spec.fat_zero: expected a finite number"),
    ("[" * 100_000, "is not valid JSON"),
])
def test_a_crafted_recipe_beside_weights_is_one_line(tmp_path, capsys, text, field):
    """The recipe (``.json``) beside weights is read for their lags, colours and fat zero: a file of the wrong
    shape names itself and the field (issue 40: before, AttributeError / TypeError tracebacks)."""
    weights = tmp_path / "w.pt"
    weights.write_bytes(infer.DEFAULT_WEIGHTS.read_bytes())
    weights.with_suffix(".json").write_text(text)
    assert main(["export", str(tmp_path / "n.onnx"), "--weights", str(weights)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("tpnet export: error: weights: the recipe") and field in err[0], err


def test_train_never_clobbers_weights_and_writes_them_whole(data, tmp_path, capsys, monkeypatch):  # noqa: F811
    # Before: `tpnet train --out W` replaced existing weights without a word, and a run killed while saving left
    # half a file. Oracles: the bytes of the file that was there, the CLI's one-line contract, and a save that
    # fails half-way (torch.save raising after writing) leaving the old weights whole.
    out = tmp_path / "w.pt"
    out.write_bytes(b"earlier weights")
    argv = ["train", str(data), "--out", str(out), "--epochs", "1", "--batch", "2", "--checkpoint",
            str(tmp_path / "ck.pt"), "--threads", "1"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "--out: expected a new file (or --overwrite)" in err and err.count("\n") == 1, err
    assert out.read_bytes() == b"earlier weights"
    real = torch.save

    def failing(obj, f, *args, **kwargs):
        real(obj, f, *args, **kwargs)
        if str(f).endswith(".pt") and ".w.pt.tmp-" in str(f):
            raise OSError(28, "No space left on device")

    monkeypatch.setattr(torch, "save", failing)
    assert main([*argv, "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert f"out: writing {out} failed, nothing written (No space left on device)" in err and err.count("\n") == 1
    assert out.read_bytes() == b"earlier weights"  # the old file whole, no temporary beside it
    assert not [p.name for p in tmp_path.iterdir() if ".tmp-" in p.name or p.name.endswith(".lock")]
    monkeypatch.setattr(torch, "save", real)
    assert main([*argv, "--overwrite"]) == 0
    assert set(infer.read_tensors(out, "weights", "TPNET weights")) >= {"stage1.0.weight"}
    assert out.with_suffix(".json").is_file()
