"""The hostile-user cases of ``campaign.py``, by class. Standard library only (the campaign must not import the
project it judges): inputs are written here (PNG by hand, pickles with ``pickle``), the command line is run as a
black box.

A case is ``Case(cls, name, argv, expect, setup)``: ``argv`` the tpnet arguments (``{d}`` = the case's own
folder, ``{pair}`` = a small valid image pair); ``expect`` "2" (must be refused: exit 2, one line) or "0|2"
(either the right result or one line); ``setup(folder)`` makes the case's files.
"""

from __future__ import annotations

import os
import pickle
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path


@dataclass
class Case:
    cls: str
    name: str
    argv: list
    expect: str = "0|2"
    setup: object = None
    runs: int = 1  # > 1: that many copies at once (concurrent writers of one --out)
    kill_after: float | None = None  # SIGKILL the run this many seconds in, then run it again
    marker: str | None = None  # a file that must never appear (a crafted pickle's payload)
    names: str | None = None  # a refusal's error line must contain this (the argument or file it is about)


def png(path: Path, width: int = 64, height: int = 48, shift: int = 0, seed: int = 1) -> None:
    """An 8-bit grey PNG of a fixed pseudo-random texture moved ``shift`` px left (stdlib only)."""
    rows, state = [], seed
    texture = []
    for _ in range((width + 16) * height):
        state = (state * 1103515245 + 12345) % 2**31
        texture.append(state >> 23)
    for y in range(height):
        start = y * (width + 16) + shift
        rows.append(b"\x00" + bytes(texture[start:start + width]))
    raw = zlib.compress(b"".join(rows))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", raw) + chunk(b"IEND", b""))


def pair(folder: Path) -> list[str]:
    folder.mkdir(parents=True, exist_ok=True)
    png(folder / "left.png", shift=4)
    png(folder / "right.png", shift=0)
    return [str(folder / "left.png"), str(folder / "right.png")]


class _Payload:
    def __init__(self, marker: str):
        self.marker = marker

    def __reduce__(self):
        return os.mkdir, (self.marker,)


RIG = ('{{"width": 64, "height": 48, "pixel_size_mm": {px}, "focal_mm": {focal}, "baseline_mm": 258, '
       '"offsets": [[-0.5, 0], [0.5, 0]], "extrinsics": {ext}}}')


def _kinds(name: str):
    """The special and crafted forms of a file called ``name``: (label, setup(folder) -> path)."""
    def missing(d):
        return d / name

    def empty(d):
        (d / name).write_bytes(b"")
        return d / name

    def noise(d):
        (d / name).write_bytes(bytes(range(256)) * 40)
        return d / name

    def truncated(d):
        png(d / "whole.png")
        (d / name).write_bytes((d / "whole.png").read_bytes()[:200])
        return d / name

    def fifo(d):
        os.mkfifo(d / name)
        return d / name

    def device(d):
        (d / name).symlink_to("/dev/zero")
        return d / name

    def folder(d):
        (d / name).mkdir()
        return d / name

    def loop(d):
        (d / name).symlink_to(d / name)
        return d / name

    def pickled(d):
        with open(d / name, "wb") as f:
            pickle.dump({"model": _Payload(str(d / "pwned"))}, f)
        return d / name

    return [("missing", missing), ("empty", empty), ("noise", noise), ("truncated", truncated), ("FIFO", fifo),
            ("/dev/zero", device), ("folder", folder), ("link loop", loop), ("pickle payload", pickled)]


def _door(cls: str, door: str, name: str, argv_of) -> list[Case]:
    out = []
    for label, make in _kinds(name):
        def setup(d, make=make):
            pair(d / "pair")
            return make(d)
        out.append(Case(cls, f"{door}: {label}", argv_of, "2", setup, marker="pwned", names=name))
    return out


def file_doors() -> list[Case]:
    """Every door that reads a file, given what no file of its kind is."""
    cases = []
    cases += _door("file doors", "left image", "l.png",
                   ["process", "{d}/l.png", "{d}/pair/right.png", "--max-disparity", "8", "--out", "{d}/o"])
    cases += _door("file doors", "rig file", "rig.json",
                   ["process", "{d}/pair/left.png", "{d}/pair/right.png", "--rig", "{d}/rig.json",
                    "--max-disparity", "8", "--out", "{d}/o"])
    cases += _door("file doors", "process --weights", "w.pt",
                   ["process", "{d}/pair/left.png", "{d}/pair/right.png", "--max-disparity", "8", "--method",
                    "tpnet", "--weights", "{d}/w.pt", "--out", "{d}/o"])
    cases += _door("file doors", "export --weights", "w.pt", ["export", "{d}/n.onnx", "--weights", "{d}/w.pt"])
    return cases


def crafted_rigs() -> list[Case]:
    """Rig files whose numbers or structure no camera has."""
    zeros = "[" + ", ".join(["0"] * 13) + "]"
    plain = RIG.format(px=0.0022, focal=4.5, ext=zeros)
    texts = {
        "pixel 1e-320": RIG.format(px="1e-320", focal=4.5, ext=zeros),
        "focal 1e308": RIG.format(px=0.0022, focal="1e308", ext=zeros),
        "extrinsics 1e300": RIG.format(px=0.0022, focal=4.5, ext="[" + ", ".join(["1e300"] * 13) + "]"),
        "5000-digit width": plain.replace('"width": 64', '"width": ' + "1" * 5000),
        "nested 100000 deep": "[" * 100_000 + "]" * 100_000,
        "a list": "[1, 2]",
        "NaN baseline": plain.replace('"baseline_mm": 258', '"baseline_mm": NaN'),
    }
    out = []
    for label, text in texts.items():
        def setup(d, text=text):
            pair(d / "pair")
            (d / "rig.json").write_text(text)
        out.append(Case("crafted rigs", label, ["process", "{d}/pair/left.png", "{d}/pair/right.png", "--rig",
                                                "{d}/rig.json", "--max-disparity", "4", "--out", "{d}/o"], "2", setup,
                        names="rig.json"))
    return out


NUMBERS = ["0", "-1", "nan", "inf", "-inf", "1e308", "-1e308", "1e-320", "1" * 5000, "abc", ""]


def option_bounds(quick: bool = False) -> list[Case]:
    """Every numeric option of the commands that run quickly, at the edges of what a number can be."""
    values = ["nan", "1e308", "1" * 5000] if quick else NUMBERS
    process = ["process", "{d}/pair/left.png", "{d}/pair/right.png", "--out", "{d}/o", "--no-figures"]
    options = {
        "process --max-disparity": (process, "--max-disparity", []),
        "process --min-disparity": (process, "--min-disparity", ["--max-disparity", "8"]),
        "process --min-confidence": (process, "--min-confidence", ["--max-disparity", "8"]),
        "process --keep-fraction": (process, "--keep-fraction", ["--max-disparity", "8"]),
        "process --memory-limit": (process, "--memory-limit", ["--max-disparity", "8"]),
        "render --width": (["render", "{d}/o", "--height", "32", "--supersample", "1"], "--width", []),
        "render --seed": (["render", "{d}/o", "--width", "48", "--height", "32", "--supersample", "1"], "--seed", []),
        "export --opset": (["export", "{d}/n.onnx"], "--opset", []),
    }
    dataset = ["dataset", "{d}/data", "--scenes", "1", "--width", "64", "--height", "48", "--supersample", "1",
               "--rig", "binocular", "--mono"]
    train = ["train", "{data}", "--rig", "binocular", "--epochs", "1", "--batch", "1", "--out", "{d}/w.pt"]
    slow = {f"dataset {o}": (dataset, o, []) for o in ("--scenes", "--test-fraction", "--seed", "--supersample",
                                                        "--curved")}
    slow.update({f"train {o}": (train, o, []) for o in ("--epochs", "--batch", "--threads", "--error-scale",
                                                        "--random-weight", "--lr-from", "--pass-every")})
    slow["flow --camera"] = (["flow", "{d}/pair/left.png", "{d}/pair/right.png", "--out", "{d}/o"], "--camera", [])
    if quick:
        options = {k: options[k] for k in ("process --max-disparity", "process --memory-limit", "export --opset")}
    out = []
    for label, (base, option, more) in slow.items() if not quick else ():  # values that must be refused fast
        for value in ("nan", "-1", "1e308", "1" * 5000, "abc"):
            shown = value if len(value) < 12 else f"{value[:3]}...({len(value)} chars)"
            out.append(Case("option bounds", f"{label} {shown!r}", [*base, *more, f"{option}={value}"], "0|2",
                            lambda d: pair(d / "pair"), names=option))
    for label, (base, option, more) in options.items():
        for value in values:
            shown = value if len(value) < 12 else f"{value[:3]}...({len(value)} chars)"
            out.append(Case("option bounds", f"{label} {shown!r}", [*base, *more, f"{option}={value}"], "0|2",
                            lambda d: pair(d / "pair"), names=option))
    return out


def outputs(quick: bool = False) -> list[Case]:
    """Output folders: two writers at once, a writer killed mid-write then run again, an output that may not be."""
    process = ["process", "{d}/pair/left.png", "{d}/pair/right.png", "--max-disparity", "8", "--out", "{d}/o"]
    rounds = 1 if quick else 3
    out = [Case("outputs", f"two runs, one --out (round {i + 1})", process, "one of 2", lambda d: pair(d / "pair"),
                runs=2) for i in range(rounds)]
    out += [Case("outputs", f"killed after {t:g} s, then run again", [*process, "--overwrite"], "0",
                 lambda d: pair(d / "pair"), kill_after=t) for t in ((4.0,) if quick else (2.0, 4.0, 6.0))]
    out.append(Case("outputs", "--out inside an input's folder", ["process", "{d}/pair/left.png",
                                                                    "{d}/pair/right.png", "--max-disparity", "8",
                                                                    "--out", "{d}/pair"], "2",
                    lambda d: pair(d / "pair")))
    out.append(Case("outputs", "--out under a file", [*process[:-1], "{d}/pair/left.png/o"], "2",
                    lambda d: pair(d / "pair")))
    out.append(Case("outputs", "non-ASCII input names", ["process", "{d}/p/gauche é.png", "{d}/p/droite ü.png",
                                                         "--max-disparity", "8", "--out", "{d}/o"], "0",
                    lambda d: (d / "p").mkdir() or png(d / "p" / "gauche é.png", shift=4) or
                    png(d / "p" / "droite ü.png")))
    return out


def _video(d: Path, frames: int = 3) -> None:
    """``d/left`` and ``d/right``, ``frames`` valid frames each (0000.png, ...)."""
    for side, shift in (("left", 4), ("right", 0)):
        (d / side).mkdir(parents=True)
        for k in range(frames):
            png(d / side / f"{k:04d}.png", shift=shift + k % 2)


def video() -> list[Case]:
    """A video (one folder of frames per camera) with a frame that no frame is, or folders that do not pair up:
    the bad frame is one ``frame N (...)`` line and exit 1 with the others written; folders, a refusal."""
    argv = ["process", "{d}/left", "{d}/right", "--max-disparity", "8", "--out", "{d}/o", "--no-figures"]
    cases = []
    for label, make in _kinds("0001.png"):
        if label in ("missing", "folder"):  # a folder named 0001.png is no frame: the counts then differ
            continue

        def setup(d, make=make):
            _video(d)
            (d / "right" / "0001.png").unlink()
            make(d / "right")
            (d / "right" / "whole.png").unlink(missing_ok=True)  # "truncated"'s source: not a frame of the video
        cases.append(Case("video", f"frame 1 of 3: {label}", argv, "1", setup, marker="pwned", names="frame 1 ("))

    def other_size(d):
        _video(d)
        png(d / "right" / "0001.png", width=72)
    cases.append(Case("video", "frame 1 of 3: another size", argv, "1", other_size, names="frame 1 ("))

    def counts(d):
        _video(d)
        (d / "right" / "0002.png").unlink()
    cases.append(Case("video", "folders of 3 and 2 frames", argv, "2", counts, names="inputs"))
    cases.append(Case("video", "an empty camera folder", argv, "2",
                      lambda d: _video(d, 0) or None, names="inputs"))
    return cases


def all_cases(quick: bool = False) -> list[Case]:
    cases = outputs(quick) + crafted_rigs() + option_bounds(quick) + file_doors() + video()
    if quick:  # a slice of every class
        cases = [c for i, c in enumerate(cases) if c.cls in ("outputs", "option bounds") or i % 4 == 0]
    return cases
