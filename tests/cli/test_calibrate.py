"""``tpnet calibrate`` input checks and its atomic, non-clobbering rig output (tpnet_gpu/cli/calibrate.py).
Oracles: the CLI contract (one-line ``tpnet calibrate: error: ...``, exit 2, nothing written) and the rig file read
back (``rigfile.read_rig``) equal to the rig written. Break tried: the existence check of --out removed (the
refusal test fails: the file is replaced)."""

from pathlib import Path

import pytest

from tpnet_gpu import cli
from tpnet_gpu.camera import Rig
from tpnet_gpu.cli.calibrate import write_rig_atomically
from tpnet_gpu.io.rigfile import read_rig


def _run(capsys, *argv):
    code = cli.main(["calibrate", *argv])
    err = capsys.readouterr().err.strip().splitlines()
    return code, err


def test_missing_scene(tmp_path, capsys):
    code, err = _run(capsys, str(tmp_path / "nope"), "--rig", "quad", "--out", str(tmp_path / "out.json"))
    assert code == 2 and len(err) == 1 and err[0].startswith("tpnet calibrate: error: SCENE:")
    assert not (tmp_path / "out.json").exists()


def test_rounds_are_the_librarys_to_refuse(tmp_path, capsys, monkeypatch):
    """``--rounds 0`` is refused by ``CalibrationConfig`` (the library's one check), in one line, before any scene
    is read; without ``--rounds`` the library's default runs."""
    from tpnet_gpu.calibration import CalibrationConfig
    from tpnet_gpu.scenes import folder

    monkeypatch.setattr(folder, "load", lambda *a, **k: pytest.fail("a scene read before --rounds was checked"))
    code, err = _run(capsys, str(tmp_path), "--rig", "quad", "--out", str(tmp_path / "o.json"), "--rounds", "0")
    assert code == 2 and len(err) == 1 and err[0] == "tpnet calibrate: error: rounds: expected an int >= 1, got 0"
    assert cli.build_parser().parse_args(["calibrate", "s", "--rig", "quad", "--out", "o.json"]).rounds is None
    with pytest.raises(ValueError, match=r"tolerance: expected a finite number of pixels > 0, got nan"):
        CalibrationConfig(tolerance=float("nan"))


def test_bad_rig_file(tmp_path, capsys):
    bad = tmp_path / "rig.json"
    bad.write_text("{not json")
    code, err = _run(capsys, str(tmp_path), "--rig", str(bad), "--out", str(tmp_path / "out.json"))
    assert code == 2 and len(err) == 1 and err[0].startswith("tpnet calibrate: error:")
    code, err = _run(capsys, str(tmp_path), "--rig", str(tmp_path / "missing.json"), "--out", str(tmp_path / "o.json"))
    assert code == 2 and len(err) == 1 and "rig file not found" in err[0]


def test_existing_out_refused(tmp_path, capsys):
    out = tmp_path / "out.json"
    out.write_text("keep")
    code, err = _run(capsys, str(tmp_path), "--rig", "quad", "--out", str(out))
    assert code == 2 and "--out" in err[0] and out.read_text() == "keep"


def test_write_rig_atomically(tmp_path):
    rig = Rig(width=320, height=240, extrinsics=(1e-4,) * 13)
    out = write_rig_atomically(rig, tmp_path / "cal.json", overwrite=False, description="test")
    assert read_rig(out) == rig
    with pytest.raises(ValueError, match="--out"):
        write_rig_atomically(rig, out, overwrite=False, description="test")
    write_rig_atomically(Rig(width=320, height=240), out, overwrite=True, description="test")
    assert read_rig(out).is_ideal() and sorted(p.name for p in Path(tmp_path).iterdir()) == ["cal.json"]
