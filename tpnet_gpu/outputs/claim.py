"""An exclusive claim on an output path, so that two runs writing one ``--out`` cannot lose each other's data.

The claim is an advisory lock (``flock``) on ``.NAME.lock`` beside the output, held from the check before any
work until the output is in place. A run without ``--overwrite`` that finds it held is refused at once, naming
the holder's pid; an ``--overwrite`` run waits for it (runs are serialised: the last one to finish wins, whole).
The holder unlinks the lock file before releasing it, and a run that wins the lock on a file someone has since
unlinked tries again, so no lock file outlives its runs and two runs never hold two files of one name.

While the claim is held no other run can be writing beside the output, so leftovers of runs killed there
(staging folders ``.NAME.tmp-*`` and set-aside old outputs ``.NAME.old-*``, recognised by the marker file each
writer puts in them) are the dead writers' and are cleaned up: a staging folder is removed, an old output whose
replacement never arrived is put back.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import re
import shutil
import sys
import time
from collections.abc import Iterator
from pathlib import Path

MARKER = ".tpnet-writer"  # inside every staging / old-output folder: {"pid": ..., "kind": ...}
WAIT_LOG_S = 2.0  # an --overwrite run says it is waiting once it has waited this long
_FILE_TEMP = re.compile(r"\.tmp-[a-z0-9_]{8}(\.[A-Za-z0-9]+)?")  # after ".NAME": tempfile.mkstemp's name


def umask() -> int:
    """The process's umask (read by setting and restoring it; the command line is single-threaded here)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def mark(folder: Path, kind: str) -> None:
    """Put the writer marker in ``folder`` (a fresh staging or old-output folder)."""
    (folder / MARKER).write_text(json.dumps({"pid": os.getpid(), "kind": kind}))


def _holder(lock: Path) -> str:
    """Who holds the claim, as the refusal says it (the pid is written just after the lock is taken, so a run
    that looks in between finds none)."""
    try:
        return f"another tpnet run (pid {int(lock.read_text().strip())})"
    except (OSError, ValueError):
        return "another tpnet run"


def _acquire(lock: Path, *, wait: bool, option: str, out: Path) -> int:
    announced, start = False, time.monotonic()
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            if not wait:
                raise ValueError(f"{option}: {out} is being written by {_holder(lock)}; wait for it to finish "
                                 "or choose another folder") from None
            if not announced and time.monotonic() - start > WAIT_LOG_S:
                print(f"{option}: waiting for {_holder(lock)}, which is writing {out}", file=sys.stderr, flush=True)
                announced = True
            time.sleep(0.1)
            continue
        try:
            same = os.fstat(fd).st_ino == os.stat(lock, follow_symlinks=False).st_ino
        except FileNotFoundError:
            same = False
        if same:  # not a file its last holder unlinked after we opened it
            os.ftruncate(fd, 0)
            os.write(fd, str(os.getpid()).encode())
            return fd
        os.close(fd)


def _dead_writers(folder: Path) -> bool:
    """Whether ``folder`` holds a writer marker whose process is gone (an unreadable marker counts as gone; this
    process's own never does)."""
    try:
        pid = int(json.loads((folder / MARKER).read_text())["pid"])
    except FileNotFoundError:
        return False
    except (OSError, ValueError, KeyError, TypeError):
        return True
    if pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except PermissionError:  # alive, someone else's
        return False
    return False


def _clean_leftovers(out: Path) -> None:
    """Remove dead writers' staging folders beside ``out``; put back an old output whose replacement never
    arrived, or move what a set-aside old output still holds back into ``out`` (only folders whose ``MARKER``
    names a process that is gone)."""
    if out.is_dir():
        (out / MARKER).unlink(missing_ok=True)  # a writer killed just after putting its output in place
    for entry in sorted(out.parent.glob(f".{out.name}.old-*")):
        kept = entry / "folder"
        if not _dead_writers(entry):
            continue
        if kept.is_dir() and not out.exists():
            os.replace(kept, out)
        elif kept.is_dir():
            for item in kept.iterdir():
                if not (out / item.name).exists():
                    os.replace(item, out / item.name)
        shutil.rmtree(entry, ignore_errors=True)
    for entry in out.parent.glob(f".{out.name}.tmp-*"):
        if entry.is_dir() and _dead_writers(entry):
            shutil.rmtree(entry, ignore_errors=True)
        elif entry.is_file() and _FILE_TEMP.fullmatch(entry.name[len(out.name) + 1:]):
            entry.unlink(missing_ok=True)  # an output_file's temporary (mkstemp's name) whose writer is gone


@contextlib.contextmanager
def claim(out: Path, *, wait: bool, option: str) -> Iterator[None]:
    """Hold the claim on ``out`` (resolved, its parent existing) for the block; clean leftovers first."""
    lock = out.parent / f".{out.name}.lock"
    try:
        fd = _acquire(lock, wait=wait, option=option, out=out)
    except OSError as exc:  # a read-only parent, a lock name that is a link or a folder
        raise ValueError(f"{option}: cannot claim {out} for writing ({exc.strerror or exc}: {lock})") from exc
    try:
        _clean_leftovers(out)
        yield
    finally:
        with contextlib.suppress(OSError):
            lock.unlink()
        os.close(fd)
