"""Progress bars and the log switch (tpnet_gpu/runtime/progress.py). Oracles: a stand-in stderr that says it is (or is
not) a terminal and records what is written; the logging records of a ``tpnet_gpu`` logger."""

import io
import logging

import pytest

from tpnet_gpu.runtime import progress


class Terminal(io.StringIO):
    def isatty(self):
        return True


def test_a_bar_only_on_a_terminal_and_not_when_switched_off(monkeypatch):
    monkeypatch.delenv(progress.ENV, raising=False)
    monkeypatch.setattr("sys.stderr", io.StringIO())  # a pipe, a file, CI: no bar
    assert not progress.enabled()
    assert list(progress.bar(range(3), desc="x")) == [0, 1, 2]
    assert "\r" not in progress.sys.stderr.getvalue()
    terminal = Terminal()
    monkeypatch.setattr("sys.stderr", terminal)
    assert progress.enabled() and not progress.enabled(False)
    assert list(progress.bar(range(3), desc="scenes")) == [0, 1, 2]
    assert "\rscenes:" in terminal.getvalue() and "/3 [" in terminal.getvalue()  # tqdm redraws at most 10/s
    monkeypatch.setenv(progress.ENV, "0")
    assert not progress.enabled()


def test_steps_draw_on_a_terminal_and_log_each_step(monkeypatch, caplog):
    monkeypatch.delenv(progress.ENV, raising=False)
    terminal = Terminal()
    monkeypatch.setattr("sys.stderr", terminal)
    caplog.set_level(logging.INFO, logger="tpnet_gpu.test")
    with progress.Steps(2, desc="demo", logger=logging.getLogger("tpnet_gpu.test")) as step:
        step("rendering")
        step("figures")
    assert "0/2 [" in terminal.getvalue() and "rendering]" in terminal.getvalue()
    assert [r.getMessage() for r in caplog.records] == ["rendering", "figures"]


def test_verbosity_levels_and_restore(monkeypatch):
    err = io.StringIO()
    monkeypatch.setattr("sys.stderr", err)
    logger = logging.getLogger("tpnet_gpu.some.module")
    before = logging.getLogger("tpnet_gpu").level
    with progress.verbosity(0):
        logger.info("hidden")
        logger.warning("shown")
    with progress.verbosity(1):
        logger.info("info line")
        logger.debug("hidden debug")
    with progress.verbosity(2):
        logger.debug("debug line")
    text = err.getvalue()
    assert "shown" in text and "INFO tpnet_gpu.some.module: info line" in text and "debug line" in text
    assert "hidden" not in text
    assert logging.getLogger("tpnet_gpu").level == before and not logging.getLogger("tpnet_gpu").handlers
    with pytest.raises(ValueError, match="level: expected a count of -v"):
        with progress.verbosity(-1):
            pass
