"""Issue 16's fuzz cases over the ``tpnet`` command line and their oracle, shared by the CI slice
(tests/fuzz/test_cli_fuzz.py) and the campaign (``tpnet bench fuzz``). Needs hypothesis (the ``test`` extra).

Drawn: a subcommand (process, render, inspect, dataset, bench) and a random list of its options with values
valid and not (0, negative, NaN, 1e309, words, empty; devices, backends, rigs, CFAs, references), over inputs
that exist or not (a small rendered scene folder, a DNG, a plain file, an empty folder, a missing path).
Runs that would be long if valid start from small sizes (render 48x32, dataset 32x32 with a bad option always
drawn, bench with an option always drawn). Oracle (cli.py's contract): exit 0, or exit 2 with the last line of
stderr ``tpnet CMD: error: ...`` (argparse's usage lines may come before it) - never a traceback or another
status. ``main`` runs in this process; outputs go to fresh folders under the fixture's directory.
"""

from __future__ import annotations

import contextlib
import io
import itertools
import re
from pathlib import Path

import numpy as np
from hypothesis import strategies as st

NUMBERS = ["4", "0", "-3", "2.5", "nan", "inf", "1e309", "abc", ""]
SIZES = ["0", "-8", "7", "20", "24", "48", "x"]
PATHS = ["SCENE", "DNG", "FILE", "EMPTY", "MISSING"]
ERROR_LINE = re.compile(r"^tpnet( [a-z_]+)*: error: ")
_counter = itertools.count()


def fixture(folder: Path) -> dict:
    """The inputs the cases name (built once per folder): a 48x32 rendered scene, one of its DNGs, a plain file,
    an empty folder and a missing path; keys are the names in ``PATHS``."""
    from tpnet_gpu.cli import main  # noqa: PLC0415

    paths = {"SCENE": folder / "scene", "DNG": folder / "scene" / "cam0.dng", "FILE": folder / "file.txt",
             "EMPTY": folder / "empty", "MISSING": folder / "missing"}
    if not paths["SCENE"].exists():
        with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
            assert main(["render", str(paths["SCENE"]), "--width", "48", "--height", "32", "--supersample", "1"]) == 0
        paths["FILE"].write_text("not an image")
        paths["EMPTY"].mkdir(exist_ok=True)
    return {k: str(v) for k, v in paths.items()}


def _options(draw, table: dict, min_size=0) -> list[str]:
    names = draw(st.lists(st.sampled_from(sorted(table)), min_size=min_size, max_size=4))
    out = []
    for name in names:
        values = table[name]
        out += [name] + ([draw(st.sampled_from(values))] if values else [])
    return out


@st.composite
def cli_case(draw) -> list[str]:
    """One argument list (module docstring); path names in ``PATHS`` and "OUT" are filled in by ``check``."""
    command = draw(st.sampled_from(["process", "render", "inspect", "dataset", "bench"]))
    if command == "process":
        inputs = draw(st.sampled_from([["SCENE"], ["DNG"] * 4, ["DNG", "DNG"], ["FILE", "FILE"], ["MISSING"],
                                       ["EMPTY"], ["SCENE", "SCENE", "SCENE"]]))
        table = {"--max-disparity": NUMBERS, "--min-disparity": NUMBERS, "--device": ["cpu", "cuda", "gpu", "0"],
                 "--backend": ["warp", "taichi", "numba"], "--rig": ["quad", "binocular", "two_quads", *PATHS],
                 "--reference": ["auto", "rig", "0", "3", "9", "-1", "x"], "--colour": ["luma", "hsv"],
                 "--cfa": ["GRBG", "RGB", ""], "--overwrite": None, "--out": PATHS, "--nope": None}
        return ["process", *inputs, "--out", "OUT", *_options(draw, table)]
    if command == "render":
        table = {"--width": SIZES, "--height": SIZES, "--bits": ["10", "11", "16", "x"], "--scene": ["demo", "nope"],
                 "--supersample": ["0", "-1", "1", "x"], "--seed": ["1", "-1", "x"], "--no-noise": None,
                 "--overwrite": None}
        out = draw(st.sampled_from(["OUT", "OUT", *PATHS]))
        return ["render", out, "--width", "48", "--height", "32", "--supersample", "1", *_options(draw, table)]
    if command == "inspect":
        return ["inspect", *draw(st.lists(st.sampled_from(PATHS), min_size=0, max_size=2))]
    if command == "dataset":
        bad = {"--scenes": ["-1", "x", "1.5"], "--width": ["0", "20", "x"], "--test-fraction": ["-0.5", "1.5", "nan"],
               "--rig": ["MISSING", "FILE", "nope"], "--device": ["gpu", "0"], "--supersample": ["0", "x"]}
        return ["dataset", "OUT", "--scenes", "1", "--width", "32", "--height", "32", "--supersample", "1",
                *_options(draw, bad, min_size=1)]
    name = draw(st.sampled_from(["tp", "accuracy", "network", "throughput", "startup", "fuzz", "nope"]))
    args = draw(st.sampled_from([["--help"], ["--nope"], ["--examples", "0"], ["--examples", "x"], ["--height", "x"]]))
    return ["bench", name, *args]


def check(argv: list[str], paths: dict, folder: Path) -> dict:
    """Run ``tpnet`` with ``argv`` (names filled in) and apply the oracle; ``failures``: [] or one name, and
    ``status``, ``stderr`` (its last line) for the record."""
    from tpnet_gpu.cli import main  # noqa: PLC0415

    names = {**paths, "OUT": str(folder / f"out{next(_counter)}")}
    argv = [names.get(a, a) for a in argv]
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            try:
                status = main(argv)
            except SystemExit as exc:  # argparse: --help (0) or a usage error (2)
                status = exc.code
    except Exception as exc:  # noqa: BLE001 - a traceback is the failure this oracle looks for
        return {"failures": [f"{argv[0]}: traceback ({type(exc).__name__}: {str(exc)[:80]})"], "status": None,
                "argv": argv}
    lines = err.getvalue().strip().splitlines()
    last = lines[-1] if lines else ""
    failures = []
    if "Traceback" in err.getvalue():
        failures.append(f"{argv[0]}: traceback on stderr")
    elif status not in (0, 2):
        failures.append(f"{argv[0]}: exit {status}")
    elif status == 2 and not ERROR_LINE.match(last):
        failures.append(f"{argv[0]}: exit 2 without a 'tpnet CMD: error:' line")
    return {"failures": failures, "status": status, "stderr": last[:200], "argv": argv}


def statuses(results: list[dict]) -> dict:
    """Counts of exit statuses (for the campaign's table)."""
    values, counts = np.unique([str(r["status"]) for r in results], return_counts=True)
    return dict(zip(values.tolist(), counts.tolist()))
