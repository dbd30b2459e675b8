"""Bad and hostile input at the ``tpnet`` command line: the regressions of issue 16's fuzz campaign and of issue
40's hostile user (each named after the failure found).
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


# --- issue 40: what a hostile user still broke ------------------------------------------------------------
def _small_pair(folder, names=("left.png", "right.png")):
    import numpy as np
    from PIL import Image

    rng = np.random.default_rng(1)
    image = rng.integers(0, 256, (48, 72), dtype=np.uint8)
    paths = [folder / name for name in names]
    Image.fromarray(image[:, 4:68]).save(paths[0])
    Image.fromarray(image[:, :64]).save(paths[1])  # the right view: the content 4 px to the left
    return [str(p) for p in paths]


def test_issue40_a_symlink_loop_as_input_is_one_line(tmp_path, capsys):
    (tmp_path / "loop").symlink_to(tmp_path / "loop")  # before: Python's RuntimeError traceback
    assert main(["process", str(tmp_path / "loop"), str(tmp_path / "loop"), "--max-disparity", "8", "--out",
                 str(tmp_path / "o")]) == 2
    assert "inputs: cannot resolve" in _one_line(capsys, "process") and not (tmp_path / "o").exists()


def test_issue40_a_rig_file_nested_too_deep_is_one_line(tmp_path, capsys):
    left, right = _small_pair(tmp_path)
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)  # before: RecursionError
    assert main(["process", left, right, "--rig", str(deep), "--max-disparity", "8", "--out",
                 str(tmp_path / "o")]) == 2
    assert "deep.json: nested too deep to be a rig file (JSON)" in _one_line(capsys, "process")


def test_issue40_non_ascii_file_names_are_processed(tmp_path, capsys):
    # before: processed in full, then refused by the point cloud's ASCII header ("'ascii' codec can't encode")
    left, right = _small_pair(tmp_path, ("gauche é.png", "droite ü.png"))
    assert main(["process", left, right, "--max-disparity", "8", "--out", str(tmp_path / "o"), "--no-figures"]) == 0
    header = (tmp_path / "o" / "points.ply").read_bytes().split(b"end_header")[0].decode("ascii")
    assert "gauche \\xe9.png" in header


def test_issue40_an_output_under_a_file_names_the_option(tmp_path, capsys):
    # before: "[Errno 17] File exists", no option named
    (tmp_path / "afile").write_text("x")
    left, right = _small_pair(tmp_path)
    assert main(["process", left, right, "--max-disparity", "8", "--out", str(tmp_path / "afile" / "o")]) == 2
    err = _one_line(capsys, "process")
    assert "--out: cannot write" in err and f"{tmp_path / 'afile'} is a file, not a folder" in err
    assert main(["export", str(tmp_path / "afile" / "n.onnx")]) == 2
    assert "is a file, not a folder" in _one_line(capsys, "export")
