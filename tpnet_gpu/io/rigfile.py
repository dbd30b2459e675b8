"""Rig calibration files (rig_file.md §1-§4): one JSON object or TOML table whose keys are the fields of
``tpnet_gpu.camera.Rig``, read into a ``Rig`` and written back from one.

Reading checks every field and names it, with what was expected and what came: unknown keys, missing required
keys, wrong types or lengths, non-positive lengths and NaN or infinite numbers are refused (``RigFileError``).
Writing checks the rig the same way first, so every file written reads back into an equal ``Rig``. JSON is read
and written; TOML is read with ``tomllib`` and written by ``_toml`` (flat keys, numbers and arrays only).
Example rigs ship in ``tpnet_gpu/rigs/`` (``examples()``); ``resolve`` turns their names into paths.
"""

from __future__ import annotations

import json
import math
import numbers
import tomllib
from pathlib import Path

import numpy as np

from tpnet_gpu.camera import DISTORTION_TERMS, EXTRINSIC_TERMS, Rig
from tpnet_gpu.io.paths import kind, regular_file

FORMAT = "tpnet-gpu rig"
VERSION = 1
SUFFIXES = (".json", ".toml")
EXAMPLES_DIR = Path(__file__).resolve().parents[1] / "rigs"
REQUIRED = ("width", "height", "pixel_size_mm", "focal_mm", "baseline_mm", "offsets")
OPTIONAL = ("distortion", "distortion_radius_mm", "principal_points", "extrinsics", "rolls_deg")
HEADER = ("format", "version", "description")
KNOWN = HEADER + REQUIRED + OPTIONAL
MIN_CAMS = 2  # the tile processor correlates pairs


class RigFileError(ValueError):
    """A rig file (or rig description) that is not valid; the message names the field."""


def _fail(source: str, field: str, expected: str, got) -> RigFileError:
    return RigFileError(f"{source}: {field}: expected {expected}, got {got!r}")


def _number(value, source: str, field: str) -> float:
    """A finite real number (not a bool) as float."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise _fail(source, field, "a number", value)
    out = float(value)
    if not math.isfinite(out):
        raise _fail(source, field, "a finite number", value)
    return out


def _length(value, source: str, field: str) -> float:
    out = _number(value, source, field)
    if out <= 0:
        raise _fail(source, field, "a positive length in mm", value)
    return out


def _size(value, source: str, field: str) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value <= 0:
        raise _fail(source, field, "a positive integer number of pixels", value)
    return int(value)


def _list(value, source: str, field: str, length: int | None, what: str) -> list:
    if isinstance(value, (str, bytes, dict)) or not hasattr(value, "__len__") or not hasattr(value, "__iter__"):
        raise _fail(source, field, f"a list of {what}", value)
    items = list(value)
    if length is not None and len(items) != length:
        raise RigFileError(f"{source}: {field}: expected {length} {what}, got {len(items)}")
    return items


def _vector(value, source: str, field: str, length: int, what: str) -> tuple:
    items = _list(value, source, field, length, what)
    return tuple(_number(v, source, f"{field}[{i}]") for i, v in enumerate(items))


def _points(value, source: str, field: str, rows: int | None) -> tuple:
    """``rows`` (or >= MIN_CAMS when None) pairs (x, y) of finite numbers."""
    items = _list(value, source, field, rows, "(x, y) rows, one per camera")
    if rows is None and len(items) < MIN_CAMS:
        raise RigFileError(f"{source}: {field}: expected at least {MIN_CAMS} cameras (x, y), got {len(items)}")
    return tuple(_vector(row, source, f"{field}[{i}]", 2, "numbers (x, y)") for i, row in enumerate(items))


# Physical bounds (rig_file.md §3): a number outside them is not a camera, and some make depth, rays or the
# search range non-finite (a 1e-320 mm pixel, a 1e308 mm lens, extrinsics of 1e300).
BOUNDS = {
    "width": (1, 65535), "height": (1, 65535),  # pixels
    "pixel_size_mm": (1e-4, 1.0), "focal_mm": (0.1, 1e4), "baseline_mm": (1e-3, 1e6),
    "distortion_radius_mm": (1e-3, 1e4), "focal_px": (10.0, 1e6),  # focal_mm / pixel_size_mm
    "offsets": (-100.0, 100.0),  # baselines
    "distortion": (-10.0, 10.0), "extrinsics": (-1.0, 1.0),  # radians and relative zooms: corrections, not poses
    "rolls_deg": (-360.0, 360.0),
}


def _bounded(value, source: str, field: str, bound: str | None = None):
    """``value`` (a number or nested tuples of them), or a ``RigFileError`` naming the first entry outside
    ``BOUNDS[bound or field]``."""
    low, high = BOUNDS[bound or field]
    flat = np.ravel(np.asarray(value, dtype=np.float64))
    bad = np.flatnonzero((flat < low) | (flat > high))
    if bad.size:
        index = "".join(f"[{int(i)}]" for i in np.unravel_index(bad[0], np.shape(value)))
        raise _fail(source, f"{field}{index}", f"a value in [{low:g}, {high:g}] (physical bounds, rig_file.md §3)",
                    value if np.ndim(value) == 0 else flat[bad[0]].item())
    return value


def _physical(rig: Rig, source: str) -> None:
    """A ``RigFileError`` when the rig's geometry is not finite where the pipeline uses it: rays of the frame's
    corners and centre, and the cameras' views of them from infinity to the largest disparity the frame holds."""
    corners = np.array([[0.0, 0.0], [rig.width, 0.0], [0.0, rig.height], [rig.width, rig.height], rig.centre])
    try:
        with np.errstate(all="ignore"):
            views = [rig.port_coordinates(corners, np.full(len(corners), d)) for d in (0.0, 1.0, float(rig.width))]
            rays = rig.virtual_rays(corners)
            depth = rig.image_to_world(corners, np.ones(len(corners)))
    except ValueError as exc:  # the lens model's own refusal (a distortion it cannot invert over the frame)
        raise RigFileError(f"{source}: {exc}") from exc
    if not all(np.isfinite(v).all() for v in (*views, rays, depth)):
        raise RigFileError(f"{source}: expected a rig whose rays and views are finite over the frame, got non-finite "
                           "geometry (check pixel_size_mm, focal_mm, distortion, extrinsics, principal_points)")


def rig_from_dict(data, source: str = "rig") -> Rig:
    """A ``Rig`` from a parsed rig file (rig_file.md §2, §3); ``source`` (e.g. the file name) starts messages.

    Raises:
        RigFileError: not a table, a key unknown or missing, or a value of the wrong type, length or sign.
    """
    if not isinstance(data, dict):
        raise RigFileError(f"{source}: expected a table (JSON object) of rig fields, got {type(data).__name__}")
    unknown = [k for k in data if k not in KNOWN]
    if unknown:
        raise RigFileError(f"{source}: unknown keys {unknown}; expected some of {list(KNOWN)}")
    missing = [k for k in REQUIRED if k not in data]
    if missing:
        raise RigFileError(f"{source}: missing keys {missing}; required: {list(REQUIRED)}")
    if "format" in data and data["format"] != FORMAT:
        raise _fail(source, "format", repr(FORMAT), data["format"])
    if "version" in data and (isinstance(data["version"], bool) or data["version"] not in range(1, VERSION + 1)):
        raise _fail(source, "version", f"an integer 1..{VERSION}", data["version"])
    if "description" in data and not isinstance(data["description"], str):
        raise _fail(source, "description", "a string", data["description"])
    kw = {name: _bounded(_size(data[name], source, name), source, name) for name in ("width", "height")}
    for name in ("pixel_size_mm", "focal_mm", "baseline_mm"):
        kw[name] = _bounded(_length(data[name], source, name), source, name)
    _bounded(kw["focal_mm"] / kw["pixel_size_mm"], source, "focal_mm / pixel_size_mm", "focal_px")
    kw["offsets"] = _bounded(_points(data["offsets"], source, "offsets", None), source, "offsets")
    cams = len(kw["offsets"])
    radius = data.get("distortion_radius_mm")
    kw["distortion_radius_mm"] = (kw["width"] * kw["pixel_size_mm"] / 2.0 if radius is None else
                                  _bounded(_length(radius, source, "distortion_radius_mm"), source,
                                           "distortion_radius_mm"))
    terms = ((DISTORTION_TERMS, "distortion", "terms (C, B, A, A5, A6, A7, A8)"),
             (EXTRINSIC_TERMS, "extrinsics", "terms (tilt0..2, az0..2, roll0..3, zoom0..2)"))
    for count, name, what in terms:
        value = data.get(name)
        kw[name] = (0.0,) * count if value is None else _bounded(_vector(value, source, name, count, what),
                                                                  source, name)
    if data.get("principal_points") is not None:
        points = _points(data["principal_points"], source, "principal_points", cams)
        for i, (x, y) in enumerate(points):  # on the sensor, give or take its own size
            if not (-kw["width"] <= x <= 2 * kw["width"] and -kw["height"] <= y <= 2 * kw["height"]):
                raise _fail(source, f"principal_points[{i}]", f"a point within a frame's size of the {kw['width']}x"
                            f"{kw['height']} sensor (physical bounds, rig_file.md §3)", [x, y])
        kw["principal_points"] = points
    if data.get("rolls_deg") is not None:
        kw["rolls_deg"] = _bounded(_vector(data["rolls_deg"], source, "rolls_deg", cams,
                                           "angles (degrees), one per camera"), source, "rolls_deg")
    try:
        rig = Rig(**kw)
    except ValueError as exc:  # Rig's own checks (none should remain after the ones above)
        raise RigFileError(f"{source}: {exc}") from exc
    _physical(rig, source)
    return rig


def _fields(rig: Rig) -> dict:
    data = {
        "width": rig.width, "height": rig.height, "pixel_size_mm": rig.pixel_size_mm, "focal_mm": rig.focal_mm,
        "baseline_mm": rig.baseline_mm, "offsets": [list(r) for r in rig.offsets],
        "distortion": list(rig.distortion), "distortion_radius_mm": rig.distortion_radius_mm,
        "extrinsics": list(rig.extrinsics),
    }
    if rig.principal_points is not None:
        data["principal_points"] = rig.principal().tolist()  # Rig also takes them flat
    if rig.rolls_deg is not None:
        data["rolls_deg"] = list(rig.rolls_deg)
    return data


def rig_to_dict(rig: Rig, description: str | None = None) -> dict:
    """The file form of ``rig``: header, then its fields (``principal_points`` / ``rolls_deg`` only when set).
    The rig is checked by ``rig_from_dict`` first (NaN, lengths, ...), so what is written reads back."""
    checked = rig_from_dict(_fields(rig), "rig")  # also turns NumPy numbers into plain ints and floats
    header = {"format": FORMAT, "version": VERSION}
    if description is not None:
        if not isinstance(description, str):
            raise _fail("rig", "description", "a string", description)
        header["description"] = description
    return {**header, **_fields(checked)}


def _suffix(path: Path, arg: str) -> str:
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise RigFileError(f"{arg}: expected a {' or '.join(SUFFIXES)} rig file, got {path.name!r}")
    return suffix


def read_rig(path) -> Rig:
    """Read a rig file (``.json`` or ``.toml``, rig_file.md §1).

    Raises:
        FileNotFoundError: no such file.
        RigFileError: another suffix, not parseable, or a field that ``rig_from_dict`` refuses.
    """
    path = Path(path)
    suffix = _suffix(path, "path")
    regular_file(path, "rig", "rig file", RigFileError)
    try:
        text = path.read_text(encoding="utf-8")
        data = json.loads(text) if suffix == ".json" else tomllib.loads(text)
    except UnicodeDecodeError as exc:
        raise RigFileError(f"{path}: not a text file ({exc})") from exc
    except (json.JSONDecodeError, tomllib.TOMLDecodeError) as exc:
        raise RigFileError(f"{path}: not valid {suffix[1:].upper()} ({exc})") from exc
    except RecursionError as exc:  # nested deeper than the parser's recursion (a crafted file)
        raise RigFileError(f"{path}: nested too deep to be a rig file ({suffix[1:].upper()})") from exc
    except ValueError as exc:  # the parsers' other refusals, e.g. an integer of more than 4300 digits
        raise RigFileError(f"{path}: not a rig file: {suffix[1:].upper()} with {exc}") from exc
    return rig_from_dict(data, str(path))


def _toml_value(value) -> str:
    if isinstance(value, str):  # a TOML basic string: JSON's escapes, plus DEL (TOML wants it escaped)
        return json.dumps(value, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)  # finite (checked); repr round-trips and is valid TOML (1e-05, 258.0)
    return "[" + ", ".join(_toml_value(v) for v in value) + "]"


def _json(data: dict) -> str:
    """One key a line, each value on its line (lists of rows too): short enough to edit by hand."""
    lines = [f"  {json.dumps(key)}: {json.dumps(value, ensure_ascii=False)}" for key, value in data.items()]
    return "{\n" + ",\n".join(lines) + "\n}\n"


def _toml(data: dict) -> str:
    return "".join(f"{key} = {_toml_value(value)}\n" for key, value in data.items())


def write_rig(rig: Rig, path, *, description: str | None = None) -> Path:
    """Write ``rig`` to ``path`` as JSON (``.json``) or TOML (``.toml``); returns the path.

    Raises:
        RigFileError: another suffix, or a rig field that would not read back (e.g. NaN).
    """
    path = Path(path)
    suffix = _suffix(path, "path")
    data = rig_to_dict(rig, description)
    text = _json(data) if suffix == ".json" else _toml(data)
    path.write_text(text, encoding="utf-8")
    return path


def examples() -> dict[str, Path]:
    """The shipped example rigs, name -> file (``tpnet_gpu/rigs/NAME.json``)."""
    return {p.stem: p for p in sorted(EXAMPLES_DIR.glob("*.json"))}


def resolve(spec) -> Path:
    """A rig file path, or the name of a shipped example (``quad``, ``binocular``, ...; a file wins)."""
    path = Path(spec)
    if kind(path) is not None:  # a file wins (read_rig refuses a folder, a FIFO or a device, naming it)
        return path
    found = examples().get(str(spec))
    if found is not None:
        return found
    raise FileNotFoundError(f"rig file not found: {spec} (nor a shipped example: {', '.join(examples())})")


def load(spec) -> Rig:
    """``read_rig(resolve(spec))``: a rig file or a shipped example's name."""
    return read_rig(resolve(spec))
