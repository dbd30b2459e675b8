"""What a path is, before anything opens it: a FIFO or a device given as an input would block a read forever
or stream without end (issue 40), a folder is not a file. Links are followed; a link loop is named as such."""

from __future__ import annotations

import os
import stat
from pathlib import Path

_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def kind(path) -> str | None:
    """"a regular file", "a folder", "a FIFO (named pipe)", "a character device", ... or None (nothing there;
    a broken link); "a link loop" for a symbolic link that leads back to itself."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return None
    except OSError as exc:  # ELOOP, ENAMETOOLONG, EACCES on a parent
        return "a link loop" if "loop" in (exc.strerror or "").lower() else f"unreadable ({exc.strerror})"
    if stat.S_ISREG(mode):
        return "a regular file"
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def regular_file(path, name: str, noun: str, error=ValueError) -> Path:
    """``path`` when it is a regular file (links followed); a ``FileNotFoundError`` when nothing is there ("left:
    image file not found: x"), else ``error`` naming ``name`` (the argument) and what the path is ("left: x:
    expected an image file, got a FIFO (named pipe)")."""
    path = Path(path)
    found = kind(path)
    if found is None:
        raise FileNotFoundError(f"{name}: {noun} not found: {path}")
    if found != "a regular file":
        article = "an" if noun[:1].lower() in "aeiou" else "a"
        raise error(f"{name}: {path}: expected {article} {noun}, got {found}")
    return path
