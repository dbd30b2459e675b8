"""Output claims (``outputs.claim`` through ``outputs.folder``): two writers of one folder, killed writers, the
umask. Oracles are process facts - exit codes, which writer's bytes the folder holds, what is left beside it,
the mode bits ``os.stat`` reports - not the module's own bookkeeping."""

import os
import signal
import stat
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from tpnet_gpu.outputs import check, claimed, output_file, output_folder

ROOT = Path(__file__).resolve().parents[2]


def _writer(tmp_path, out, name: str, body: str, overwrite: bool = False) -> Path:
    """A script that claims ``out``, waits for the go file, writes ``a`` and ``b`` with its name, slowly."""
    script = tmp_path / f"{name}.py"
    head = textwrap.dedent(f"""\
        import os, signal, sys, time
        from pathlib import Path
        sys.path.insert(0, {str(ROOT)!r})
        from tpnet_gpu.outputs import claimed, output_folder
        go = Path({str(tmp_path / "go")!r})
        try:
            with claimed({str(out)!r}, overwrite={overwrite}) as out:
                Path({str(tmp_path / name)!r} + ".ready").touch()
                while not go.exists():
                    time.sleep(0.01)
                with output_folder(out, overwrite={overwrite}) as folder:
        """)
    tail = "except ValueError as exc:\n    print(exc, file=sys.stderr)\n    sys.exit(2)\n"
    script.write_text(head + textwrap.indent(textwrap.dedent(body).strip() + "\n", " " * 12) + tail)
    return script


SLOW_WRITE = """
(folder / "a").write_text(NAME)
time.sleep(0.3)
(folder / "b").write_text(NAME)
"""


def _leftovers(parent: Path) -> list:
    return sorted(p.name for p in parent.iterdir() if ".tmp-" in p.name or ".old-" in p.name or ".lock" in p.name)


def _start(script: Path):
    return subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@pytest.mark.parametrize("round_", range(3))
def test_of_two_simultaneous_writers_exactly_one_succeeds_and_its_result_is_whole(tmp_path, round_):
    out = tmp_path / "out"
    runs = [_start(_writer(tmp_path, out, n, SLOW_WRITE.replace("NAME", repr(n)))) for n in ("one", "two")]
    for _ in range(500):  # both past their start-up: one holds the claim, the other has been refused or waits
        if any(p.poll() is not None for p in runs) or any((tmp_path / f"{n}.ready").exists() for n in ("one", "two")):
            break
        subprocess.run(["sleep", "0.02"])
    (tmp_path / "go").touch()
    codes = [p.wait(timeout=120) for p in runs]
    errors = [p.stderr.read() for p in runs]
    assert sorted(codes) == [0, 2], errors
    winner = ("one", "two")[codes.index(0)]
    assert "is being written by another tpnet run" in errors[codes.index(2)] or "holds files" in errors[codes.index(2)]
    assert {p.name: p.read_text() for p in out.iterdir()} == {"a": winner, "b": winner}
    assert _leftovers(tmp_path) == []


def test_overwrite_writers_take_turns_and_the_folder_holds_one_of_them_whole(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "a").write_text("old")
    runs = [_start(_writer(tmp_path, out, n, SLOW_WRITE.replace("NAME", repr(n)), overwrite=True))
            for n in ("one", "two")]
    (tmp_path / "go").touch()
    codes = [p.wait(timeout=120) for p in runs]
    assert codes == [0, 0], [p.stderr.read() for p in runs]
    contents = {p.name: p.read_text() for p in out.iterdir()}
    assert contents in ({"a": "one", "b": "one"}, {"a": "two", "b": "two"})
    assert _leftovers(tmp_path) == []


@pytest.mark.parametrize("when", ["while writing", "between the renames"])
def test_a_killed_writer_leaves_nothing_the_next_run_does_not_clean(tmp_path, when):
    out = tmp_path / "out"
    out.mkdir()
    (out / "a").write_text("old")
    if when == "while writing":
        body = """(folder / "a").write_text("new")\nos.kill(os.getpid(), signal.SIGKILL)"""
    else:  # the old output has been set aside and the new one is not in place yet
        body = """(folder / "a").write_text("new")
import tpnet_gpu.outputs.folder as f
real, calls = f.os.replace, []
def dying(src, dst):
    calls.append(dst)
    real(src, dst)
    if len(calls) == 1:
        os.kill(os.getpid(), signal.SIGKILL)
f.os.replace = dying"""
    (tmp_path / "go").touch()
    done = subprocess.run([sys.executable, str(_writer(tmp_path, out, "dying", body, overwrite=True))],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == -signal.SIGKILL, done.stderr[-2000:]
    assert [n for n in _leftovers(tmp_path) if ".tmp-" in n or ".old-" in n]  # the kill did leave something
    if when == "between the renames":
        assert not out.exists()
    with claimed(out, overwrite=True) as resolved:  # the next run: the old output back, the leftovers gone
        assert (resolved / "a").read_text() == "old"
        with output_folder(resolved, overwrite=True) as folder:
            (folder / "b").write_text("next")
    assert {p.name: p.read_text() for p in out.iterdir()} == {"a": "old", "b": "next"}
    assert _leftovers(tmp_path) == []


def test_a_live_holder_is_named_and_a_second_claim_is_refused_at_once(tmp_path):
    out = tmp_path / "out"
    with claimed(out, overwrite=False):
        script = f"import sys; sys.path.insert(0, {str(ROOT)!r})\nfrom tpnet_gpu.outputs import claimed\n" \
                 f"with claimed({str(out)!r}, overwrite=False): pass"
        done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
        assert done.returncode != 0 and f"being written by another tpnet run (pid {os.getpid()})" in done.stderr
    assert _leftovers(tmp_path) == [] and not out.exists()  # nothing written: the folder made for it is not left


def test_outputs_follow_the_umask(tmp_path):
    previous = os.umask(0o027)
    try:
        with output_folder(tmp_path / "out", overwrite=False) as folder:
            (folder / "a").write_text("x")
        with output_file(tmp_path / "f.bin", overwrite=False) as tmp:
            tmp.write_bytes(b"x")
    finally:
        os.umask(previous)
    assert stat.S_IMODE(os.stat(tmp_path / "out").st_mode) == 0o750
    assert stat.S_IMODE(os.stat(tmp_path / "f.bin").st_mode) == 0o640


def test_root_and_mount_points_are_refused_before_any_work(tmp_path):
    for mount in ("/", "/proc"):
        if os.path.ismount(mount):
            with pytest.raises(ValueError, match="--out: expected a folder that can be replaced, got the mount point"):
                check(mount, overwrite=True)


def test_a_write_past_the_file_size_limit_names_the_file_and_leaves_nothing(tmp_path):
    # Oracle: the kernel's RLIMIT_FSIZE (Python ignores SIGXFSZ, so the write fails with EFBIG); before, the
    # message was the writer's "6144 requested and 4028 written", naming no file.
    script = textwrap.dedent(f"""
        import resource, sys
        sys.path.insert(0, {str(ROOT)!r})
        from tpnet_gpu.outputs import output_file, output_folder
        resource.setrlimit(resource.RLIMIT_FSIZE, (50_000, 50_000))
        for make in (lambda: output_folder({str(tmp_path / "out")!r}, overwrite=False),
                     lambda: output_file({str(tmp_path / "f.bin")!r}, overwrite=False)):
            try:
                with make() as target:
                    path = target / "big.tif" if target.is_dir() else target
                    with open(path, "wb") as f:
                        f.write(b"x" * 100_000)
            except OSError as exc:
                print(exc)
    """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    lines = done.stdout.strip().splitlines()
    assert lines == [f"--out: writing {tmp_path / 'out' / 'big.tif'} failed, nothing written (File too large)",
                     f"--out: writing {tmp_path / 'f.bin'} failed, nothing written (File too large)"], done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == []
