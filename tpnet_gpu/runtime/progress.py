"""Progress bars of the long commands (tqdm, on stderr) and the CLI's log switch.

A bar is shown only where someone can watch it: stderr is a terminal and the environment does not say
``TPNET_PROGRESS=0`` (CI logs, pipes and redirected runs get no carriage-return noise). Library functions take
``progress: bool`` (default True: "show it if the terminal allows"); ``False`` never shows one.

``verbosity(level)`` gives the ``tpnet_gpu`` loggers a stderr handler at WARNING (0), INFO (``tpnet -v``) or
DEBUG (``tpnet -vv``) for the duration of one command; the library itself only logs.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
from collections.abc import Iterable, Iterator

ENV = "TPNET_PROGRESS"  # "0": never show a bar (any other value, or unset: show it on a terminal)
LEVELS = (logging.WARNING, logging.INFO, logging.DEBUG)  # tpnet, tpnet -v, tpnet -vv
LOG_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"


def enabled(progress: bool = True) -> bool:
    """Whether to draw a bar: ``progress`` asked for one, ``TPNET_PROGRESS`` is not "0", stderr is a terminal."""
    if not progress or os.environ.get(ENV, "1").strip() == "0":
        return False
    isatty = getattr(sys.stderr, "isatty", None)
    return bool(isatty and isatty())


def bar(iterable: Iterable | None = None, *, desc: str, total: int | None = None, unit: str = "it",
        progress: bool = True):
    """A tqdm bar on stderr over ``iterable`` (or one to ``update`` by hand: ``total`` steps), drawn only when
    ``enabled(progress)``; a disabled bar still iterates and accepts ``update`` / ``set_postfix_str``."""
    from tqdm import tqdm  # noqa: PLC0415 - declared dependency, imported on use (start-up, docs/platform.md §4)

    return tqdm(iterable, desc=desc, total=total, unit=unit, file=sys.stderr, leave=False,
                disable=not enabled(progress), dynamic_ncols=True)


class Steps:
    """A bar over the named steps of one command (``total`` of them): ``steps("rendering")`` starts the next
    step, showing its name; ``steps.close()`` (or the ``with`` block's end; closing twice is fine) removes the bar,
    so a report printed after it starts on a clean line. Each step is logged
    at INFO on ``logger`` too, so ``tpnet -v`` tells the same story in a log."""

    def __init__(self, total: int, *, desc: str, logger: logging.Logger, progress: bool = True):
        self._bar = bar(desc=desc, total=total, unit="step", progress=progress)
        self._log = logger
        self._started = False
        self._closed = False

    def __call__(self, step: str) -> None:
        if self._started:
            self._bar.update(1)
        self._started = True
        self._bar.set_postfix_str(step)
        self._log.info("%s", step)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self._started:
            self._bar.update(1)
        self._bar.close()

    def __enter__(self) -> Steps:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@contextlib.contextmanager
def verbosity(level: int) -> Iterator[logging.Logger]:
    """For the block: the ``tpnet_gpu`` loggers at ``LEVELS[level]`` (0 WARNING, 1 INFO, 2 or more DEBUG) with a
    handler on the current stderr; the handler and the previous level are removed / restored after it."""
    if isinstance(level, bool) or not isinstance(level, int) or level < 0:
        raise ValueError(f"level: expected a count of -v (an int >= 0), got {level!r}")
    logger = logging.getLogger("tpnet_gpu")
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter(LOG_FORMAT, datefmt="%H:%M:%S"))
    previous = logger.level
    logger.setLevel(LEVELS[min(level, len(LEVELS) - 1)])
    logger.addHandler(handler)
    try:
        yield logger
    finally:
        logger.removeHandler(handler)
        logger.setLevel(previous)
