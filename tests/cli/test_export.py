"""``tpnet export`` (tpnet_gpu/cli/export.py): writes a valid ONNX file with the documented inputs and outputs,
refuses to clobber one, and ends bad input with one line (exit 2). Oracles: onnx's own model checker and the
documented interface (network.md §12); the numbers are checked in tests/net/test_export.py."""

import sys

import pytest

from tpnet_gpu.cli import main


def test_export_refuses_an_existing_file_and_missing_weights(tmp_path, capsys):
    old = tmp_path / "net.onnx"
    old.write_bytes(b"keep me")
    assert main(["export", str(old)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("tpnet export: error: path: expected a new file (or --overwrite)") and err.count("\n") == 1
    assert old.read_bytes() == b"keep me"
    assert main(["export", str(tmp_path / "new.onnx"), "--weights", str(tmp_path / "none.pt")]) == 2
    assert "no TPNET weights there" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["net.onnx"]


@pytest.mark.parametrize("missing", ["onnx", "onnxscript"])
def test_export_without_the_onnx_extra_is_one_line_naming_it(tmp_path, capsys, monkeypatch, missing):
    # Oracle: the optional extra's packages made unimportable (None in sys.modules), as on an install without
    # the extra: one line naming the package and the extra, exit 2, no file written.
    monkeypatch.setitem(sys.modules, missing, None)
    assert main(["export", str(tmp_path / "net.onnx")]) == 2
    err = capsys.readouterr().err
    assert err == (f"tpnet export: error: ONNX export needs the '{missing}' package: "
                   "pip install 'tpnet-gpu[onnx]'\n")
    assert not list(tmp_path.iterdir())


@pytest.mark.slow
def test_export_writes_a_checked_onnx_file_and_overwrites_on_request(tmp_path, capsys):
    onnx = pytest.importorskip("onnx", reason="the onnx extra is not installed (pip install 'tpnet-gpu[onnx]')")
    pytest.importorskip("onnxscript", reason="the onnx extra is not installed (pip install 'tpnet-gpu[onnx]')")
    path = tmp_path / "net.onnx"
    path.write_bytes(b"old")
    assert main(["export", str(path), "--overwrite"]) == 0
    captured = capsys.readouterr()
    assert "tiles_y, tiles_x >= 2 dynamic" in captured.out
    assert "Warning" not in captured.err and "torchvision" not in captured.err  # the exporter's chatter stays off
    model = onnx.load(str(path))
    assert [(i.domain, i.version) for i in model.opset_import if i.domain in ("", "ai.onnx")] == [("", 18)]
    onnx.checker.check_model(model, full_check=True)
    shapes = {v.name: [d.dim_param or d.dim_value for d in v.type.tensor_type.shape.dim]
              for v in (*model.graph.input, *model.graph.output)}
    assert shapes == {"layers": ["tiles_y", "tiles_x", 4, 9, 9], "target": ["tiles_y", "tiles_x"],
                      "disparity": ["tiles_y", "tiles_x"]}
    assert [p.name for p in tmp_path.iterdir()] == ["net.onnx"]  # no temporary file left beside it


def test_export_refuses_an_opset_the_installed_onnx_cannot_write(tmp_path, capsys):
    # Before: `--opset 99999` printed the version converter's traceback, exited 0 and wrote opset 18.
    onnx = pytest.importorskip("onnx", reason="the onnx extra is not installed (pip install 'tpnet-gpu[onnx]')")
    pytest.importorskip("onnxscript", reason="the onnx extra is not installed (pip install 'tpnet-gpu[onnx]')")
    highest = onnx.defs.onnx_opset_version()  # the oracle: what the installed onnx says it knows
    for opset in (highest + 1, 99999):
        assert main(["export", str(tmp_path / "net.onnx"), "--opset", str(opset)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [f"tpnet export: error: opset: expected an int in 18..{highest} (the installed onnx knows no "
                       f"later one), got {opset}"]
    assert not list(tmp_path.iterdir())
