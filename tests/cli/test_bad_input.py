"""Issue 16 regressions of the ``tpnet`` command line (each named after the failure the campaign found).
Oracle: the CLI's contract (cli.py docstring): bad input is one line ``tpnet CMD: error: ...`` and exit 2, found
before any work; a bug of ours (a TypeError) keeps its traceback."""

import pytest

from tpnet_gpu import cli
from tpnet_gpu.cli import main


def _one_line(capsys, command: str) -> str:
    err = capsys.readouterr().err
    assert err.startswith(f"tpnet {command}: error: ") and err.count("\n") == 1, err
    return err


def test_issue16_process_device_cuda_without_a_gpu_is_one_line(tmp_path, capsys):
    import warp as wp

    if wp.is_cuda_available():
        pytest.skip("a CUDA device is present")
    assert main(["render", str(tmp_path / "s"), "--width", "48", "--height", "32", "--supersample", "1"]) == 0
    capsys.readouterr()
    # before: a traceback from Warp and exit 1
    assert main(["process", str(tmp_path / "s"), "--device", "cuda", "--out", str(tmp_path / "o")]) == 2
    assert "device: 'cuda' asked for, but no CUDA device is present" in _one_line(capsys, "process")
    assert main(["process", str(tmp_path / "s"), "--device", "gpu", "--out", str(tmp_path / "o")]) == 2
    assert "device: expected 'cpu', 'cuda', 'cuda:N'" in _one_line(capsys, "process")


def test_issue16_out_naming_a_file_fails_before_any_work(tmp_path, monkeypatch, capsys):
    # before: refused only after 17 s of work. Oracle: the inputs are never read.
    from tpnet_gpu.io import stereo_io

    monkeypatch.setattr(stereo_io, "load_inputs", lambda *a, **k: pytest.fail("inputs read before --out checked"))
    (tmp_path / "file").write_text("x")
    (tmp_path / "scene").mkdir()
    assert main(["process", str(tmp_path / "scene"), "--out", str(tmp_path / "file")]) == 2
    assert "--out: expected a folder, got the file" in _one_line(capsys, "process")


@pytest.mark.parametrize("argv, message", [
    (["--width", "0"], "--width: expected a multiple of 8 that is at least 24 (LibRaw reads no smaller raw), got 0"),
    (["--height", "-8"], "--height: expected a multiple of 8 that is at least 24"),
    (["--width", "20"], "--width: expected a multiple of 8 that is at least 24"),
], ids=["width-0", "height-negative", "width-20"])
def test_issue16_render_width_0_is_a_clear_message(tmp_path, capsys, argv, message):
    # before: "zero-size array to reduction operation" after rendering, or "negative dimensions are not allowed"
    assert main(["render", str(tmp_path / "r"), *argv]) == 2
    assert message in _one_line(capsys, "render")
    assert not (tmp_path / "r").exists()


def test_issue16_internal_type_error_keeps_its_traceback(monkeypatch, tmp_path):
    # before: any TypeError became a one-line "bad input", hiding bugs
    def buggy(args):
        raise TypeError("unsupported operand type(s) for +: 'int' and 'str'")

    parser = cli.build_parser()
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    parser._subparsers._group_actions[0].choices["inspect"].set_defaults(func=buggy)
    with pytest.raises(TypeError, match="unsupported operand"):
        main(["inspect", str(tmp_path)])
