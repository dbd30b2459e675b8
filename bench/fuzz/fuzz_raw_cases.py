"""Issue 16's fuzz cases over the raw readers (``rawio.read_raw`` through rawpy/LibRaw, ``rawio.read_tiff_raw``)
and their oracle, shared by the CI slice (tests/fuzz/test_rawio_fuzz.py) and the campaign (``tpnet bench fuzz``).
Needs hypothesis (the ``test`` extra).

Drawn: a small file - a DNG from ``rawio.write_dng`` (12/14/16 bits, any of the 4 CFAs, a black level), a TIFF
mosaic, or a non-Bayer file (an RGB TIFF, a 3-D stack, a float or int8 TIFF) - then one mutation: none, random
bytes flipped anywhere or in the header (the first 512 bytes: IFD entries, tags, offsets), truncation, junk
appended, or an empty file; TIFFs are read with a drawn CFA, sometimes not a Bayer name. Oracle: each read gives
either a ``RawFrame`` of an even 2-D uint16 mosaic with one of the 4 CFAs, or a ``RawFormatError`` naming the
file, or (a bad CFA name only) a ``ValueError`` naming ``cfa`` - never another exception, a crash or a hang.
LibRaw is native code, so the reads run in a child process (``run``): a crash is counted with the case it hit,
and the child restarts after it.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import strategies as st

CFAS = ("GRBG", "RGGB", "BGGR", "GBRG")
KINDS = ("dng", "tiff", "rgb_tiff", "stack_tiff", "float_tiff", "int8_tiff")
MUTATIONS = ("none", "flip", "flip_header", "truncate", "append", "empty")
HEADER = 512  # bytes: the TIFF header and (for these small files) the IFD and its tags
BATCH_SECONDS = 120  # a child reading a batch of files longer than this counts as a hang


@st.composite
def raw_case(draw) -> dict:
    """One file to write and read (module docstring); a JSON-able dict."""
    return dict(kind=draw(st.sampled_from(KINDS)), cfa=draw(st.sampled_from(CFAS)),
                read_cfa=draw(st.sampled_from(CFAS + ("RGB", "gRbG"))), bits=draw(st.sampled_from([12, 14, 16])),
                black=draw(st.sampled_from([0, 64, 256])), height=draw(st.sampled_from([24, 32, 48])),
                mutation=draw(st.sampled_from(MUTATIONS)), seed=draw(st.integers(0, 2**32 - 1)),
                count=draw(st.integers(1, 64)))


def write(case: dict, path: Path) -> Path:
    """Write ``case``'s file at ``path`` (suffix .dng or .tif) and mutate it; returns the path."""
    import tifffile  # noqa: PLC0415

    from tpnet_gpu.io import rawio  # noqa: PLC0415

    rng = np.random.default_rng(case["seed"])
    shape = (case["height"], 48)
    data = rng.integers(0, 1 << case["bits"], shape, dtype=np.uint16)
    path = path.with_suffix(".dng" if case["kind"] == "dng" else ".tif")
    if case["kind"] == "dng":
        rawio.write_dng(path, data, case["cfa"], black_level=case["black"], bits=case["bits"])
    else:
        arrays = {"tiff": data, "rgb_tiff": np.stack([data] * 3, axis=-1), "stack_tiff": np.stack([data] * 2),
                  "float_tiff": data.astype(np.float64) / 7, "int8_tiff": (data >> 8).astype(np.int8)}
        tifffile.imwrite(path, arrays[case["kind"]], photometric="rgb" if case["kind"] == "rgb_tiff" else None,
                         metadata=None)
    blob = bytearray(path.read_bytes())
    mutation = case["mutation"]
    if mutation in ("flip", "flip_header"):
        top = min(len(blob), HEADER) if mutation == "flip_header" else len(blob)
        for _ in range(case["count"]):
            blob[int(rng.integers(top))] = int(rng.integers(256))
    elif mutation == "truncate":
        blob = blob[: int(rng.integers(len(blob)))]
    elif mutation == "append":
        blob += rng.integers(0, 256, case["count"] * 16, dtype=np.uint8).tobytes()
    elif mutation == "empty":
        blob = bytearray()
    path.write_bytes(bytes(blob))
    return path


def judge(case: dict, path: Path) -> str | None:
    """Read the file (in this process) and apply the oracle: None when it held, else the failure's name."""
    from tpnet_gpu.io import rawio  # noqa: PLC0415

    try:
        if case["kind"] == "dng":
            frame = rawio.read_raw(path)
        else:
            frame = rawio.read_tiff_raw(path, case["read_cfa"])
    except rawio.RawFormatError as exc:
        return None if str(path) in str(exc) else "RawFormatError not naming the file"
    except ValueError as exc:
        bad_cfa = case["kind"] != "dng" and case["read_cfa"] not in CFAS
        return None if bad_cfa and str(exc).startswith("cfa:") else f"ValueError: {str(exc)[:80]}"
    except Exception as exc:  # noqa: BLE001 - any other exception fails the oracle
        return f"raised {type(exc).__name__}"
    data = frame.data
    if data.ndim != 2 or data.shape[0] % 2 or data.shape[1] % 2 or frame.cfa not in CFAS:
        return "read a mosaic that is not an even 2-D Bayer one"
    if data.dtype != np.uint16 and case["kind"] == "dng":
        return "read a DNG whose data is not uint16"
    return None


def run(cases: list[dict]) -> list[str | None]:
    """Write and read every case in a child process; per case None (the oracle held) or a failure's name
    ("crash (exit N)" when the child died on it, "hang" when a batch ran out of time). The child restarts after
    a crash, so one bad file costs only itself."""
    results: list[str | None] = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp) / "cases.json"
        out = Path(tmp) / "results.jsonl"
        while len(results) < len(cases):
            rest = cases[len(results):]
            work.write_text(json.dumps(rest))
            out.write_text("")
            try:
                child = subprocess.run([sys.executable, "-m", "tpnet_gpu.bench.fuzz.fuzz_raw_cases", str(work), str(out)],
                                       capture_output=True, text=True, timeout=BATCH_SECONDS)
                code = child.returncode
            except subprocess.TimeoutExpired:
                code = None
            done = [json.loads(line)["failure"] for line in out.read_text().splitlines()]
            results += done
            if len(done) < len(rest):  # the child stopped on the next case
                results.append("hang" if code is None else f"crash (exit {code})")
    return results


def _child(work: Path, out: Path) -> None:
    cases = json.loads(work.read_text())
    with tempfile.TemporaryDirectory() as tmp, out.open("a") as log:
        for i, case in enumerate(cases):
            path = write(case, Path(tmp) / f"case{i}")
            log.write(json.dumps({"failure": judge(case, path)}) + "\n")
            log.flush()  # what the parent reads if the next case kills this process


if __name__ == "__main__":
    _child(Path(sys.argv[1]), Path(sys.argv[2]))
