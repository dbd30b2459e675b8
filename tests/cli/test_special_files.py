"""Every door of ``tpnet`` that reads a file, given what is not a regular file (issue 40 item 4): a FIFO (a read
blocks until someone writes: before, `export --weights FIFO` hung), a character device behind a link with the
right suffix (/dev/zero streams without end), a folder. Oracle: the OS made each kind (``os.mkfifo``, the
device node), and the CLI's contract - one line naming the argument and the kind, exit 2, within seconds
(``signal.alarm`` turns a hang into a failure), nothing written."""

import os
import signal
from pathlib import Path

import pytest

from tests.cli.test_bad_input import _one_line, _small_pair
from tpnet_gpu.cli import main


@pytest.fixture
def no_hang():
    def hung(signum, frame):
        raise TimeoutError("the command blocked on a special file")

    previous = signal.signal(signal.SIGALRM, hung)
    signal.alarm(60)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, previous)


def _special(tmp_path: Path, kind: str, name: str) -> Path:
    path = tmp_path / kind / name
    path.parent.mkdir(exist_ok=True)
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "device":
        if not os.path.exists("/dev/zero"):
            pytest.skip("no /dev/zero here")
        path.symlink_to("/dev/zero")
    else:
        path.mkdir()
    return path


WORDS = {"fifo": "a FIFO (named pipe)", "device": "a character device", "folder": "a folder"}

DOORS = {  # name -> (file name, argv from (pair, special, out), the argument the message names)
    "left image": ("l.png", lambda p, s, o: ["process", str(s), p[1], "--max-disparity", "8", "--out", o], "left"),
    "right image": ("r.png", lambda p, s, o: ["process", p[0], str(s), "--max-disparity", "8", "--out", o],
                    "right"),
    "rig file": ("rig.json", lambda p, s, o: ["process", *p, "--rig", str(s), "--max-disparity", "8", "--out", o],
                 "rig"),
    "process weights": ("w.pt", lambda p, s, o: ["process", *p, "--max-disparity", "8", "--method", "tpnet",
                                                 "--weights", str(s), "--out", o], "weights"),
    "export weights": ("w.pt", lambda p, s, o: ["export", o + ".onnx", "--weights", str(s)], "weights"),
    "flow frame": ("f.png", lambda p, s, o: ["flow", p[0], str(s), "--out", o], "frame"),
}


@pytest.mark.parametrize("kind", sorted(WORDS))
@pytest.mark.parametrize("door", sorted(DOORS))
def test_a_special_file_at_every_door_is_one_line(tmp_path, capsys, no_hang, door, kind):
    name, argv, argument = DOORS[door]
    if kind == "folder" and door.endswith("weights"):
        pytest.skip("a folder of weights is refused as 'no TPNET weights there' by the pipeline's own check")
    pair = _small_pair(tmp_path)
    special = _special(tmp_path, kind, name)
    out = str(tmp_path / "o")
    command = argv(pair, special, out)
    code = main(command)
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    if kind == "folder" and door == "flow frame":  # a folder is a frame too: a scene folder's
        assert "is not a scene folder" in err, err
    else:
        assert f"{argument}: " in err and WORDS[kind] in err, err
    assert not (tmp_path / "o").exists() and not (tmp_path / "o.onnx").exists()
