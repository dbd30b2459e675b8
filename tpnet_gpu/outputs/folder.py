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

Both hold an exclusive claim on the output (``outputs.claim``) while they write; a command that works before it
writes takes the claim before the work with ``claimed(out, ...)`` and writes inside it, so of two runs on one
``--out`` without ``--overwrite`` one is refused at once, and ``--overwrite`` runs take turns. Folders and files
are made with the permissions the umask gives (not the 0700 / 0600 of a private temporary).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

from tpnet_gpu.outputs.claim import MARKER, claim, mark, umask

_HELD: set = set()  # outputs this process holds the claim on (``claimed``)


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
    if out.is_dir() and os.path.ismount(out):  # it cannot be renamed aside, and its parent is another device's
        raise ValueError(f"{option}: expected a folder that can be replaced, got the mount point {out} (write into "
                         "a folder inside it)")
    if out.is_dir() and any(out.iterdir()) and not overwrite:
        raise ValueError(f"{option}: expected an empty or new folder (or --overwrite), got {out}, which holds files")
    return out


def _make_parent(out: Path, option: str) -> Path | None:
    """Make ``out``'s missing parents; return the topmost one made (None: it existed), to remove on failure."""
    missing = [p for p in reversed(out.parents) if not p.exists()]
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"{option}: cannot make the folder {out.parent} ({exc.strerror or exc})") from exc
    return missing[0] if missing else None


@contextlib.contextmanager
def _holding(path: Path, verify, *, overwrite: bool, option: str) -> Iterator[Path]:
    """Hold the exclusive claim on the checked, resolved ``path`` for the block (``outputs.claim``: refused at once
    without ``overwrite`` when another run holds it, else waiting its turn), ``verify()`` again once it is ours
    (the run before may have written it); parents made for it are removed when the block fails before anything
    is written there."""
    made = _make_parent(path, option)
    try:
        with claim(path, wait=overwrite, option=option):
            verify()
            _HELD.add(path)
            try:
                yield path
            finally:
                _HELD.discard(path)
    except BaseException:
        if made is not None and not any(p.is_file() for p in made.rglob("*")):  # only the folders made here
            shutil.rmtree(made, ignore_errors=True)
        raise


def claimed(out, *, overwrite: bool, inputs: Iterable = (), option: str = "--out"):
    """Check ``out`` (``check``) and hold the exclusive claim on it for the block (a context manager yielding
    ``out`` resolved): a command that works before it writes takes it first and writes with ``output_folder``
    inside."""
    out = check(out, overwrite=overwrite, inputs=inputs, option=option)
    return _holding(out, lambda: check(out, overwrite=overwrite, inputs=inputs, option=option),
                    overwrite=overwrite, option=option)


@contextlib.contextmanager
def output_folder(out, *, overwrite: bool, inputs: Iterable = (), option: str = "--out",
                  keep_others: bool = True) -> Iterator[Path]:
    """Check and claim ``out`` (``claimed``; already held by this process inside ``claimed``), yield a temporary
    folder to write into, and put it in place as ``out`` when the block ends without an exception (else remove it
    and leave ``out`` as it was). ``keep_others`` False: the old folder's other files go too (a command
    refreshing its own earlier output, ``tpnet demo``)."""
    resolved = _resolve(out, option)
    held = contextlib.nullcontext(resolved) if resolved in _HELD else claimed(out, overwrite=overwrite,
                                                                               inputs=inputs, option=option)
    with held as out:
        staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=out.parent))
        try:
            mark(staging, "staging")
            os.chmod(staging, 0o777 & ~umask())
            yield staging
        except OSError as exc:  # a full disk, a file-size limit: the writers' messages name no file
            newest = _newest(staging)
            shutil.rmtree(staging, ignore_errors=True)
            raise OSError(f"{option}: writing {out / newest if newest else out} failed, nothing written "
                          f"({exc.strerror or exc})") from exc
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)
            raise
        try:
            _put_in_place(staging, out, keep_others)
        except OSError as exc:  # EBUSY, EXDEV, EROFS on the renames: the old output stays (module docstring)
            shutil.rmtree(staging, ignore_errors=True)
            raise OSError(f"{option}: cannot put the new output in place as {out} ({exc.strerror or exc})") from exc


def _newest(folder: Path) -> str | None:
    """The name of the file written last in ``folder`` (the one a failed write was writing), or None."""
    files = [p for p in folder.iterdir() if p.is_file() and p.name != MARKER]
    return max(files, key=lambda p: p.stat().st_mtime_ns).name if files else None


def _put_in_place(staging: Path, out: Path, keep_others: bool = True) -> None:
    if not out.exists():
        os.replace(staging, out)
        (out / MARKER).unlink()
        return
    old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-", dir=out.parent))
    try:
        mark(old, "old output")  # a run killed from here on leaves it for the next claim to put back
        os.replace(out, old / "folder")
    except OSError:  # e.g. EBUSY: the old output cannot be moved; it stays where it is
        shutil.rmtree(old, ignore_errors=True)
        raise
    try:
        os.replace(staging, out)
    except OSError:
        os.replace(old / "folder", out)  # the old output back, whole
        shutil.rmtree(old, ignore_errors=True)
        raise
    (out / MARKER).unlink()
    kept = old / "folder"
    for entry in kept.iterdir() if keep_others else ():  # the old files this output does not replace stay
        if not (out / entry.name).exists():
            os.replace(entry, out / entry.name)
    shutil.rmtree(old, ignore_errors=True)


def _check_file(path: Path, *, overwrite: bool, option: str) -> None:
    if path.is_dir():
        raise ValueError(f"{option}: expected a file, got the folder {path}")
    if path.exists() and not overwrite:
        raise ValueError(f"{option}: expected a new file (or --overwrite), got {path}, which exists")


def claimed_file(path, *, overwrite: bool, option: str = "--out"):
    """``claimed`` for one file: check ``path`` (an existing one refused without ``overwrite``) and hold the claim
    on it for the block - a command that works before it writes (``tpnet train``) writes it with ``output_file``
    inside. Yields ``path`` resolved."""
    path = _resolve(path, option)
    _parents_are_folders(path, option)
    _check_file(path, overwrite=overwrite, option=option)
    return _holding(path, lambda: _check_file(path, overwrite=overwrite, option=option), overwrite=overwrite,
                    option=option)


@contextlib.contextmanager
def output_file(path, *, overwrite: bool, option: str = "--out") -> Iterator[Path]:
    """Yield a temporary path beside the file ``path`` to write, renamed to ``path`` when the block ends without an
    exception (else removed); an existing ``path`` is refused without ``overwrite`` (a ``ValueError`` naming
    ``option``), before any work. The claim on ``path`` is held while it writes (``claimed_file``; already held
    by this process inside it)."""
    resolved = _resolve(path, option)
    held = contextlib.nullcontext(resolved) if resolved in _HELD else claimed_file(path, overwrite=overwrite,
                                                                                   option=option)
    with held as path:
        handle, name = tempfile.mkstemp(prefix=f".{path.name}.tmp-", suffix=path.suffix, dir=path.parent)
        os.fchmod(handle, 0o666 & ~umask())
        os.close(handle)
        tmp = Path(name)
        try:
            yield tmp
        except OSError as exc:  # the writer's message names the temporary file, or none
            tmp.unlink(missing_ok=True)
            raise OSError(f"{option}: writing {path} failed, nothing written ({exc.strerror or exc})") from exc
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
        os.replace(tmp, path)
