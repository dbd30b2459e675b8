"""Output folders of the command line, written whole or not at all (issue 16: outputs clobbered or half-written).

``output_folder(out, overwrite=..., inputs=...)`` checks the folder before any work (a non-empty one is refused
without ``overwrite``; one that holds, or is, an input is always refused), yields a fresh temporary folder beside
it to write into, and only when the block ends without an exception puts it in place: the old folder is renamed
aside, the new one renamed to ``out``, the old folder's files that the new output does not replace are moved
into it, and the old folder is removed. A failure or a kill while writing leaves the old output as it was (a kill
also leaves a ``.NAME.tmp-*`` folder beside it); a kill between the two renames leaves the old output whole in
``.NAME.old-*/folder``.

``output_file(path, overwrite=...)`` does the same for one file: it yields a temporary path beside it to write,
renamed to ``path`` only when the block ends without an exception.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path


def _inside(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def _resolve(path, option: str) -> Path:
    """``path`` made absolute with its links followed, or a ``ValueError`` naming ``option`` (a link loop)."""
    try:
        return Path(path).resolve()
    except (RuntimeError, OSError) as exc:  # Python raises RuntimeError for a symlink loop
        raise ValueError(f"{option}: cannot resolve {path} ({exc})") from exc


def _parents_are_folders(path: Path, option: str) -> None:
    """A ``ValueError`` naming ``option`` when an existing parent of ``path`` is a file (no folder can be made
    there; the OS would say only "File exists")."""
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise ValueError(f"{option}: cannot write {path}: {parent} is a file, not a folder")
            return


def check(out, *, overwrite: bool, inputs: Iterable = (), option: str = "--out") -> Path:
    """``out`` resolved, or a ``ValueError`` naming ``option`` when it may not be written (module docstring)."""
    out = _resolve(out, option)
    _parents_are_folders(out, option)
    for source in inputs:
        source = _resolve(source, "inputs")
        if _inside(source, out) or _inside(out, source):
            raise ValueError(f"{option}: expected a folder apart from the inputs, got {out} (input {source})")
    if out.exists() and not out.is_dir():
        raise ValueError(f"{option}: expected a folder, got the file {out}")
    if out.is_dir() and any(out.iterdir()) and not overwrite:
        raise ValueError(f"{option}: expected an empty or new folder (or --overwrite), got {out}, which holds files")
    return out


@contextlib.contextmanager
def output_folder(out, *, overwrite: bool, inputs: Iterable = (), option: str = "--out",
                  keep_others: bool = True) -> Iterator[Path]:
    """Check ``out`` (``check``), yield a temporary folder to write into, and put it in place as ``out`` when the
    block ends without an exception (else remove it and leave ``out`` as it was). ``keep_others`` False: the old
    folder's other files go too (a command refreshing its own earlier output, ``tpnet demo``)."""
    out = check(out, overwrite=overwrite, inputs=inputs, option=option)
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=out.parent))
    try:
        yield staging
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    _put_in_place(staging, out, keep_others)


def _put_in_place(staging: Path, out: Path, keep_others: bool = True) -> None:
    if not out.exists():
        os.replace(staging, out)
        return
    old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-", dir=out.parent))
    os.replace(out, old / "folder")
    os.replace(staging, out)
    kept = old / "folder"
    for entry in kept.iterdir() if keep_others else ():  # the old files this output does not replace stay
        if not (out / entry.name).exists():
            os.replace(entry, out / entry.name)
    shutil.rmtree(old, ignore_errors=True)


@contextlib.contextmanager
def output_file(path, *, overwrite: bool, option: str = "--out") -> Iterator[Path]:
    """Yield a temporary path beside the file ``path`` to write, renamed to ``path`` when the block ends without an
    exception (else removed); an existing ``path`` is refused without ``overwrite`` (a ``ValueError`` naming
    ``option``), before any work."""
    path = _resolve(path, option)
    _parents_are_folders(path, option)
    if path.is_dir():
        raise ValueError(f"{option}: expected a file, got the folder {path}")
    if path.exists() and not overwrite:
        raise ValueError(f"{option}: expected a new file (or --overwrite), got {path}, which exists")
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, name = tempfile.mkstemp(prefix=f".{path.name}.tmp-", suffix=path.suffix, dir=path.parent)
    os.close(handle)
    tmp = Path(name)
    try:
        yield tmp
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    os.replace(tmp, path)
