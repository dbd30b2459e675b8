"""Raw Bayer frames in and out: camera raws via rawpy/LibRaw, mosaic TIFFs, synthetic DNGs and scene folders.

Convention: a frame is the ``(H, W)`` mosaic as stored, H and W even; ``cfa`` ("GRBG", "RGGB", "BGGR", "GBRG")
names the top-left 2x2 cell of the *visible* area, row-major, both greens "G"; ``black_level`` is ``(2, 2)`` per
CFA site ``[row parity, column parity]`` in image layout (not LibRaw's R, G, B, G2 channel order). DNGs use the
tifffile recipe LibRaw reads back bit-exact (platform.md §3): uncompressed strips, 16-bit container, bit depth in
WhiteLevel; LibRaw refuses images under 22 pixels a side.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rawpy
import tifffile

from tpnet_gpu.io.paths import regular_file
from tpnet_gpu.tables import cfa_red_position

SCENE_FORMAT = "tpnet-gpu scene"
SCENE_VERSION = 1
SCENE_JSON = "scene.json"
GROUND_TRUTH_NPZ = "ground_truth.npz"
TIFF_SUFFIXES = (".tif", ".tiff")
DNG_BITS = (12, 14, 16)
LIBRAW_MIN_SIDE = 22  # LibRaw rejects smaller images as "Unsupported file format"
_DNG_COLOUR_CODE = {"R": 0, "G": 1, "B": 2}  # CFAPattern codes with CFAPlaneColor (0, 1, 2)
_XYZ_TO_SRGB = ((3.2406, -1.5372, -0.4986), (-0.9689, 1.8758, 0.0415), (0.0557, -0.2040, 1.0570))
_NAME_RE = re.compile(r"^[A-Za-z0-9_-]+$")


class RawFormatError(ValueError):
    """A file that is not a readable Bayer raw (or scene folder) of the expected form."""


@dataclass(frozen=True, eq=False)
class RawFrame:
    """One camera's raw mosaic.

    Attributes:
        data: ``(H, W)`` uint16 raw values as stored (float32 for float TIFF mosaics); H, W even.
        cfa: CFA pattern of the top-left 2x2 cell, e.g. "GRBG".
        black_level: ``(2, 2)`` float64 black level per CFA site ``[row parity, column parity]``.
        white_level: saturation value, in the units of ``data``.
        source: where the frame came from (file path), for messages.
    """

    data: np.ndarray
    cfa: str
    black_level: np.ndarray
    white_level: float
    source: str = ""

    def __post_init__(self):
        _check_mosaic(self.data, "data")
        if self.data.dtype not in (np.uint16, np.float32):
            raise TypeError(f"data: expected uint16 (or float32) raw values, got {self.data.dtype}")
        cfa_red_position(self.cfa)
        object.__setattr__(self, "black_level", _site_levels(self.black_level, "black_level"))
        object.__setattr__(self, "white_level", float(self.white_level))

    def normalised(self) -> np.ndarray:
        """``(H, W)`` float32: data minus the per-site black level, not clipped (what the tile processor gets)."""
        h, w = self.data.shape
        return self.data.astype(np.float32) - np.tile(self.black_level.astype(np.float32), (h // 2, w // 2))


@dataclass(frozen=True, eq=False)
class SceneFolder:
    """A scene folder read back: ``frames`` (one per camera), ``ground_truth`` arrays, ``camera`` dict."""

    frames: list[RawFrame]
    ground_truth: dict[str, np.ndarray]
    camera: dict
    folder: Path


def _check_mosaic(data: np.ndarray, name: str, error: type[Exception] = ValueError) -> None:
    if data.ndim != 2:
        raise error(f"{name}: expected a 2-D Bayer mosaic, got shape {tuple(data.shape)}")
    if data.shape[0] % 2 or data.shape[1] % 2:
        raise error(f"{name}: expected even height and width (whole 2x2 CFA cells), got {tuple(data.shape)}")


def _site_levels(value, name: str) -> np.ndarray:
    """A scalar or ``(2, 2)`` level as a ``(2, 2)`` float64 array per CFA site."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        return np.full((2, 2), float(arr))
    if arr.shape != (2, 2):
        raise ValueError(f"{name}: expected a scalar or shape (2, 2) per CFA site, got shape {arr.shape}")
    return arr.copy()


def _existing(path) -> Path:
    return regular_file(path, "raw", "raw file", RawFormatError)


def _bayer_layout(raw, path: Path) -> str:
    """CFA string of the visible area from LibRaw's colour indices; RawFormatError when not a 2x2 Bayer."""
    try:
        pattern = raw.raw_pattern
    except NotImplementedError as exc:  # rawpy raises it for unusual LibRaw filter codes
        raise RawFormatError(f"{path}: not a Bayer sensor ({exc})") from exc
    desc = raw.color_desc.decode(errors="replace")
    if pattern is None or raw.raw_type != rawpy.RawType.Flat:
        raise RawFormatError(f"{path}: not a Bayer mosaic (no CFA pattern; raw type {raw.raw_type.name})")
    if raw.num_colors != 3 or desc != "RGBG":
        raise RawFormatError(f"{path}: expected an RGB Bayer sensor (colours 'RGBG'), got {raw.num_colors} "
                             f"colours {desc!r}")
    if pattern.shape != (2, 2):
        raise RawFormatError(f"{path}: expected a 2x2 Bayer CFA, got a {pattern.shape[0]}x{pattern.shape[1]} "
                             "pattern (e.g. X-Trans)")
    cfa = "".join(desc[i] for i in pattern.ravel())
    try:
        cfa_red_position(cfa)
    except ValueError:
        raise RawFormatError(f"{path}: CFA {cfa!r} is not one of the 4 Bayer layouts") from None
    return cfa


def read_raw(path) -> RawFrame:
    """Read a camera raw (any Bayer file LibRaw reads: DNG, CR2, NEF, ...) via ``rawpy.imread``.

    Args:
        path: file path.

    Returns:
        RawFrame with ``data`` the ``(H, W)`` visible area (``raw_image_visible``) as uint16, ``cfa`` of that
        area, ``black_level`` ``(2, 2)`` per site (from LibRaw's per-channel levels) and ``white_level``.

    Raises:
        FileNotFoundError: no such file.
        RawFormatError: LibRaw cannot read it (corrupt, truncated, unsupported; LibRaw's message included), or
            it is not a 2x2 RGB Bayer mosaic, or its visible area is ambiguous (odd size, shape disagreeing
            with LibRaw's sizes, or colours not repeating the 2x2 pattern).
    """
    path = _existing(path)
    try:
        with rawpy.imread(str(path)) as raw:
            cfa = _bayer_layout(raw, path)
            sizes = raw.sizes
            data = raw.raw_image_visible.copy()  # a view into the RawPy object: copy inside the `with`
            colours = raw.raw_colors_visible.copy()
            per_channel = np.asarray(raw.black_level_per_channel, dtype=np.float64)
            white = float(raw.white_level)
    except rawpy.LibRawError as exc:  # LibRaw's messages are bytes, e.g. b'Input/output error'
        msg = exc.args[0].decode(errors="replace") if exc.args and isinstance(exc.args[0], bytes) else str(exc)
        raise RawFormatError(f"{path}: LibRaw cannot read it ({type(exc).__name__}: {msg})") from exc
    if data.shape != (sizes.height, sizes.width) or data.shape[0] % 2 or data.shape[1] % 2:
        raise RawFormatError(f"{path}: ambiguous visible area: raw {(sizes.raw_height, sizes.raw_width)}, "
                             f"visible {data.shape} (margins top {sizes.top_margin}, left {sizes.left_margin}); "
                             "expected even sides matching LibRaw's sizes")
    cell = colours[:2, :2]
    if not np.array_equal(colours, np.tile(cell, (data.shape[0] // 2, data.shape[1] // 2))):
        raise RawFormatError(f"{path}: ambiguous visible area: colours do not repeat the 2x2 {cfa} pattern")
    return RawFrame(data.astype(np.uint16, copy=False), cfa, per_channel[cell], white, str(path))


def read_tiff_raw(path, cfa: str, *, black_level=0.0, white_level=None) -> RawFrame:
    """Read a single-page 2-D TIFF holding a CFA mosaic.

    Args:
        path: file path.
        cfa: CFA pattern of the top-left cell ("GRBG", "RGGB", "BGGR", "GBRG").
        black_level: scalar or ``(2, 2)`` per CFA site.
        white_level: saturation; default the dtype maximum (255, 65535) for integers, 1.0 for floats.

    Returns:
        RawFrame with ``(H, W)`` data: uint16 for 8/16-bit integer TIFFs (values unchanged), float32 for floats.

    Raises:
        FileNotFoundError: no such file.
        RawFormatError: unreadable, multi-page, not 2-D, odd sides, or an unsupported sample type.
    """
    path = _existing(path)
    cfa_red_position(cfa)
    try:
        with tifffile.TiffFile(path) as tif:
            pages, data = len(tif.pages), tif.pages[0].asarray()
    except Exception as exc:  # tifffile raises TiffFileError, ValueError, ... for bad or truncated files
        raise RawFormatError(f"{path}: not a readable TIFF ({type(exc).__name__}: {exc})") from exc
    if pages != 1:
        raise RawFormatError(f"{path}: expected a single-page TIFF, got {pages} pages")
    _check_mosaic(data, str(path), RawFormatError)
    if data.dtype in (np.uint8, np.uint16):
        default_white = float(np.iinfo(data.dtype).max)
        data = data.astype(np.uint16)
    elif data.dtype.kind == "f":
        default_white, data = 1.0, data.astype(np.float32)
    else:
        raise RawFormatError(f"{path}: expected 8/16-bit unsigned or float samples, got {data.dtype}")
    white = default_white if white_level is None else float(white_level)
    return RawFrame(data, cfa, black_level, white, str(path))


def write_dng(path, data, cfa: str, *, black_level=0, white_level=None, bits: int = 16) -> Path:
    """Write an uncompressed strip DNG of a CFA mosaic that ``read_raw`` reads back bit-exact.

    Args:
        path: output file (overwritten).
        data: ``(H, W)`` integer mosaic, H and W even and >= 22, values in ``[0, 2**bits - 1]``.
        cfa: CFA pattern of the top-left cell.
        black_level: integer scalar, or ``(2, 2)`` per CFA site (written with BlackLevelRepeatDim (2, 2)).
        white_level: integer saturation value; default ``2**bits - 1``.
        bits: sensor bit depth, 12, 14 or 16 (the container is always 16-bit).

    Returns:
        The path written.
    """
    arr = np.asarray(data)
    _check_mosaic(arr, "data")
    if min(arr.shape) < LIBRAW_MIN_SIDE:
        raise ValueError(f"data: expected both sides >= {LIBRAW_MIN_SIDE} (LibRaw rejects smaller images), "
                         f"got {arr.shape}")
    if arr.dtype.kind not in "ui":
        raise TypeError(f"data: expected an integer (uint16) array, got {arr.dtype}")
    if bits not in DNG_BITS:
        raise ValueError(f"bits: expected one of {DNG_BITS}, got {bits!r}")
    top = (1 << bits) - 1
    if arr.min() < 0 or arr.max() > top:
        raise ValueError(f"data: expected values in [0, {top}] for bits={bits}, got [{arr.min()}, {arr.max()}]")
    cfa_red_position(cfa)  # validates the name
    black = _site_levels(black_level, "black_level")
    white = top if white_level is None else white_level
    # white first: black is checked against it (white_level=0 used to be blamed on black_level, issue 16)
    if isinstance(white, bool) or not isinstance(white, (int, float, np.integer, np.floating)) \
            or not 0 < white <= top or white != int(white):
        raise ValueError(f"white_level: expected an integer in (0, {top}] for bits={bits}, got {white!r}")
    if black.min() < 0 or np.any(black != np.round(black)) or black.max() >= white:
        raise ValueError(f"black_level: expected integers in [0, white_level={white}), got {black.tolist()}")
    uniform = bool(np.all(black == black[0, 0]))
    black_values = (int(black[0, 0]),) if uniform else tuple(int(v) for v in black.ravel())

    def ratio(values, den=10000):
        return tuple(v for x in values for v in (int(round(x * den)), den))

    tags = [
        (50706, "B", 4, (1, 4, 0, 0), True),  # DNGVersion
        (50707, "B", 4, (1, 1, 0, 0), True),  # DNGBackwardVersion
        (50708, "s", 0, "tpnet-gpu synthetic", True),  # UniqueCameraModel
        (33421, "H", 2, (2, 2), True),  # CFARepeatPatternDim
        (33422, "B", 4, tuple(_DNG_COLOUR_CODE[c] for c in cfa), True),  # CFAPattern
        (50710, "B", 3, (0, 1, 2), True),  # CFAPlaneColor
        (50711, "H", 1, 1, True),  # CFALayout: rectangular
        (50713, "H", 2, (1, 1) if uniform else (2, 2), True),  # BlackLevelRepeatDim
        (50714, "H", len(black_values), black_values, True),  # BlackLevel (row-major sites)
        (50717, "H", 1, int(white), True),  # WhiteLevel
        (50721, "2i", 9, ratio(np.ravel(_XYZ_TO_SRGB)), True),  # ColorMatrix1 (XYZ -> camera = sRGB)
        (50778, "H", 1, 21, True),  # CalibrationIlluminant1: D65
        (50728, "2I", 3, ratio((1.0, 1.0, 1.0)), True),  # AsShotNeutral
        (271, "s", 0, "tpnet-gpu", True),  # Make
        (272, "s", 0, "synthetic", True),  # Model
    ]
    path = Path(path)
    tifffile.imwrite(path, arr.astype(np.uint16), photometric="cfa", compression=None, subfiletype=0,
                     extratags=tags, metadata=None)
    return path


def check_frames(frames) -> None:
    """Raise RawFormatError naming the first camera whose size or CFA differs from camera 0's."""
    if not frames:
        raise ValueError("frames: expected at least one frame, got none")
    ref = frames[0]
    for i, f in enumerate(frames[1:], start=1):
        for what, mine, first in (("size", f.data.shape, ref.data.shape), ("CFA", f.cfa, ref.cfa)):
            if mine != first:
                raise RawFormatError(f"camera {i}: {what} {mine} differs from camera 0's {first} "
                                     f"({f.source} vs {ref.source})")


def read_frames(paths, cfa: str | None = None, *, black_level=0.0, white_level=None) -> list[RawFrame]:
    """Read one frame per camera and check that all match (size and CFA).

    ``.tif``/``.tiff`` files go through ``read_tiff_raw`` (``cfa``, ``black_level``, ``white_level`` apply and
    ``cfa`` is required); every other suffix through ``read_raw`` (levels and CFA from the file).

    Returns:
        ``cams`` RawFrames in the order of ``paths``.
    """
    paths = [Path(p) for p in paths]
    if not paths:
        raise ValueError("paths: expected at least one file, got none")
    frames = []
    for p in paths:
        if p.suffix.lower() in TIFF_SUFFIXES:
            if cfa is None:
                raise ValueError(f"cfa: required to read the TIFF mosaic {p}, got None")
            frames.append(read_tiff_raw(p, cfa, black_level=black_level, white_level=white_level))
        else:
            frames.append(read_raw(p))
    check_frames(frames)
    return frames


def stack_normalised(frames) -> np.ndarray:
    """``(cams, H, W)`` float32 stack of ``frame.normalised()``, after ``check_frames``."""
    check_frames(frames)
    return np.stack([f.normalised() for f in frames])


def write_scene(folder, raws, cfa: str, *, black_level=0, white_level=None, ground_truth: dict | None = None,
                camera: dict | None = None, bits: int = 16) -> Path:
    """Write a scene folder (created if needed): one DNG per camera, ground truth, then ``scene.json`` last.

    Layout: ``cam0.dng`` .. ``camN-1.dng``, ``ground_truth.npz`` (every array, compressed), ``<name>.tif``
    (float32) for each 2-D float ground-truth array, ``scene.json`` (format, version, cfa, levels, files, camera).

    Args:
        folder: output folder.
        raws: ``(cams, H, W)`` integer array or a sequence of ``(H, W)`` mosaics.
        cfa, black_level, white_level, bits: as ``write_dng``, shared by all cameras.
        ground_truth: name -> array; names of letters, digits, ``_``, ``-``. 2-D float arrays also go to
            ``<name>.tif`` (float32).
        camera: JSON-serialisable camera description (geometry, intrinsics, ...).

    Returns:
        The folder.
    """
    ground_truth = {} if ground_truth is None else dict(ground_truth)
    camera = {} if camera is None else camera
    try:
        if not isinstance(camera, dict):
            raise TypeError(f"got {type(camera).__name__}")
        json.dumps(camera)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"camera: expected a JSON-serialisable dict ({exc})") from exc
    for name in ground_truth:
        if not isinstance(name, str) or not _NAME_RE.match(name):
            raise ValueError(f"ground_truth: expected names of letters, digits, '_' or '-', got {name!r}")
    if len(raws) == 0:
        raise ValueError("raws: expected at least one camera mosaic, got none")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    white = (1 << bits) - 1 if white_level is None else white_level
    files = []
    for i, raw in enumerate(raws):
        files.append(f"cam{i}.dng")
        write_dng(folder / files[-1], raw, cfa, black_level=black_level, white_level=white, bits=bits)
    arrays = {k: np.asarray(v) for k, v in ground_truth.items()}
    np.savez_compressed(folder / GROUND_TRUTH_NPZ, **arrays)
    tiffs = []
    for name, arr in arrays.items():
        if arr.ndim == 2 and arr.dtype.kind == "f":
            tiffs.append(f"{name}.tif")
            tifffile.imwrite(folder / tiffs[-1], arr.astype(np.float32))
    meta = {"format": SCENE_FORMAT, "version": SCENE_VERSION, "cfa": cfa, "bits": bits,
            "black_level": _site_levels(black_level, "black_level").tolist(), "white_level": white,
            "cameras": files, "ground_truth": GROUND_TRUTH_NPZ, "ground_truth_tiffs": tiffs, "camera": camera}
    (folder / SCENE_JSON).write_text(json.dumps(meta, indent=2))
    return folder


def read_scene(folder) -> SceneFolder:
    """Read a scene folder written by ``write_scene``; frames are checked to match and to carry the JSON's CFA.

    Raises:
        FileNotFoundError: no ``scene.json``, or a camera / ground-truth file it lists is missing.
        RawFormatError: ``scene.json`` is not valid JSON, not a scene description, or of a newer version.
    """
    folder = Path(folder)
    meta_path = folder / SCENE_JSON
    if not meta_path.is_file():
        raise FileNotFoundError(f"{meta_path}: missing {SCENE_JSON}, so {folder} is not a scene folder")
    try:
        meta = json.loads(meta_path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise RawFormatError(f"{meta_path}: not valid JSON ({exc})") from exc
    keys = ("format", "version", "cfa", "cameras", "ground_truth", "camera")
    missing = [k for k in keys if k not in meta] if isinstance(meta, dict) else list(keys)
    if missing or meta["format"] != SCENE_FORMAT:
        raise RawFormatError(f"{meta_path}: expected a {SCENE_FORMAT!r} description with keys {', '.join(keys)}; "
                             f"missing {missing}")
    if not isinstance(meta["version"], int) or meta["version"] > SCENE_VERSION:
        raise RawFormatError(f"{meta_path}: expected format version <= {SCENE_VERSION} (an int), got "
                             f"{meta['version']!r}")
    cams = meta["cameras"]
    if not isinstance(cams, list) or not cams or not all(isinstance(n, str) for n in cams):
        raise RawFormatError(f"{meta_path}: cameras: expected a non-empty list of file names, got {cams!r}")
    for name in [*meta["cameras"], meta["ground_truth"]]:
        if not (folder / name).is_file():
            raise FileNotFoundError(f"{folder / name}: file listed in {SCENE_JSON} is missing")
    frames = read_frames([folder / name for name in meta["cameras"]])
    if frames[0].cfa != meta["cfa"]:
        raise RawFormatError(f"{meta_path}: cfa {meta['cfa']!r} differs from the cameras' {frames[0].cfa!r}")
    with np.load(folder / meta["ground_truth"], allow_pickle=False) as npz:
        ground_truth = {k: npz[k] for k in npz.files}
    return SceneFolder(frames, ground_truth, meta["camera"], folder)
