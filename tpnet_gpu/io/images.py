"""Ordinary images in (``read_image``: PNG through Pillow, TIFF through tifffile; rig_file.md §6) and small PNG
previews out: raw mosaics as half-size RGB, disparity maps with a colour ramp (Pillow)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tpnet_gpu import tables
from tpnet_gpu.io.paths import regular_file

MIN_IMAGE_SIDE = 8  # one tile step: a smaller image holds less than one tile
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
TIFF_SIGNATURES = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")  # classic and BigTIFF, both byte orders


class ImageFormatError(ValueError):
    """A file that is not an image ``read_image`` can use; the message names the argument and the file."""


@dataclass(frozen=True, eq=False)
class ImageData:
    """One ordinary image as stored (no scaling, no gamma change).

    Attributes:
        data: ``(H, W)`` grey or ``(H, W, 3)`` RGB float32 sample values (alpha dropped); finite.
        bits: bit depth of the samples' units, 8 or 16; None for float TIFFs.
        white_level: the largest sample value of that depth (``2**bits - 1``); 1.0 for float TIFFs.
        source: the file, for messages.
        alpha: an alpha channel was dropped.
    """

    data: np.ndarray
    bits: int | None
    white_level: float
    source: str
    alpha: bool = False

    @property
    def height(self) -> int:
        return self.data.shape[0]

    @property
    def width(self) -> int:
        return self.data.shape[1]

    @property
    def is_colour(self) -> bool:
        return self.data.ndim == 3


def read_image(path, *, name: str = "path") -> ImageData:
    """Read a PNG or TIFF image (8/16-bit grey, grey + alpha, RGB or RGBA; float TIFFs too) as float32.

    TIFF files (recognised by their first bytes) go through tifffile, everything else through Pillow (PNG, and
    any other single-frame format it reads in 8 bits, e.g. JPEG). Alpha is dropped; a MINISWHITE TIFF is
    inverted so that white is high. Pillow reads only the top 8 bits of a 16-bit colour PNG, so one is refused
    (save it as a 16-bit TIFF).

    Args:
        path: the image file.
        name: what to call the argument in messages (e.g. "left").

    Raises:
        FileNotFoundError: no such file.
        ImageFormatError: a folder, not an image, unreadable (corrupt, truncated), several pages or frames,
            samples of another type or layout (e.g. a 4-D stack or a Bayer CFA), NaN or infinite samples, or
            a side under ``MIN_IMAGE_SIDE`` pixels.
    """
    path = regular_file(path, name, "image file", ImageFormatError)
    where = f"{name}: {path}"
    with open(path, "rb") as f:
        head = f.read(32)
    if head[:4] in TIFF_SIGNATURES:
        data, bits, white, alpha = _read_tiff(path, where)
    else:
        data, bits, white, alpha = _read_pillow(path, head, where)
    if data.ndim == 3 and data.shape[2] == 1:
        data = data[..., 0]
    data = np.ascontiguousarray(data, dtype=np.float32)
    if min(data.shape[:2]) < MIN_IMAGE_SIDE:
        raise ImageFormatError(f"{where}: expected an image of at least {MIN_IMAGE_SIDE}x{MIN_IMAGE_SIDE} pixels, "
                               f"got {data.shape[1]}x{data.shape[0]}")
    if not np.all(np.isfinite(data)):
        raise ImageFormatError(f"{where}: expected finite samples, got NaN or infinity")
    return ImageData(data, bits, white, str(path), alpha)


def _read_pillow(path: Path, head: bytes, where: str) -> tuple[np.ndarray, int, float, bool]:
    from PIL import Image  # noqa: PLC0415 - Pillow comes with scikit-image

    if head[:8] == PNG_SIGNATURE and len(head) >= 26 and head[24] == 16 and head[25] in (2, 4, 6):
        raise ImageFormatError(f"{where}: a 16-bit colour PNG; Pillow reads only the top 8 bits of its samples "
                               "(save it as a 16-bit TIFF, or as 16-bit grey PNGs)")
    try:
        with Image.open(path) as im:
            frames = getattr(im, "n_frames", 1)
            im.load()
            if im.mode == "1":
                im = im.convert("L")
            elif im.mode in ("P", "PA"):
                im = im.convert("RGBA" if im.mode == "PA" or "transparency" in im.info else "RGB")
            mode, arr = im.mode, np.asarray(im)
    except Exception as exc:  # Pillow raises UnidentifiedImageError, OSError, SyntaxError, ... for bad files
        raise ImageFormatError(f"{where}: not a readable image (PNG, TIFF, or another format Pillow reads): "
                               f"{type(exc).__name__}: {exc}") from exc
    if frames != 1:
        raise ImageFormatError(f"{where}: expected a single image, got {frames} frames")
    if mode == "L":
        return arr, 8, 255.0, False
    if mode in ("LA", "La", "RGB", "RGBA", "RGBX", "RGBa"):
        alpha = mode in ("LA", "La", "RGBA", "RGBa")
        return (arr[..., :3] if arr.shape[2] >= 3 else arr[..., :1]), 8, 255.0, alpha
    if mode.startswith("I;16") or (mode == "I" and arr.size and arr.min() >= 0 and arr.max() <= 65535):
        return arr, 16, 65535.0, False
    raise ImageFormatError(f"{where}: expected grey or RGB(A) samples of 8 or 16 bits, got Pillow mode {mode!r}")


def _read_tiff(path: Path, where: str) -> tuple[np.ndarray, int | None, float, bool]:
    import tifffile  # noqa: PLC0415

    try:
        with tifffile.TiffFile(path) as tif:
            pages, shape = len(tif.pages), tif.series[0].shape if tif.series else None
            page = tif.pages[0]
            photometric, axes = page.photometric, page.axes
            data = page.asarray() if pages == 1 else None
    except Exception as exc:  # tifffile raises TiffFileError, ValueError, ... for bad or truncated files
        raise ImageFormatError(f"{where}: not a readable TIFF ({type(exc).__name__}: {exc})") from exc
    if pages != 1:
        raise ImageFormatError(f"{where}: expected one 2-D image (H, W) or (H, W, 3|4), got {pages} pages "
                               f"(shape {shape})")
    ph = tifffile.PHOTOMETRIC
    if photometric == ph.CFA:
        raise ImageFormatError(f"{where}: a raw Bayer mosaic (photometric CFA, e.g. a DNG), not an ordinary image; "
                               "raw files: rawio.read_raw, or `tpnet process --rig FILE`")
    if data.ndim == 3 and axes.endswith("SYX"):
        data = np.moveaxis(data, 0, -1)  # planar RGB
    if data.ndim not in (2, 3):
        raise ImageFormatError(f"{where}: expected a 2-D image (H, W) or (H, W, samples), got shape {data.shape}")
    samples = 1 if data.ndim == 2 else data.shape[2]
    if photometric in (ph.MINISBLACK, ph.MINISWHITE) and samples <= 2:
        data = data if data.ndim == 2 else data[..., 0]
    elif photometric == ph.RGB and samples in (3, 4):
        data = data[..., :3]
    else:
        name = getattr(photometric, "name", photometric)
        raise ImageFormatError(f"{where}: expected grey (1-2 samples) or RGB (3-4 samples), got photometric {name} "
                               f"with {samples} samples")
    if data.dtype in (np.uint8, np.uint16):
        bits = data.dtype.itemsize * 8
    elif data.dtype.kind == "f":
        bits = None
    else:
        raise ImageFormatError(f"{where}: expected 8/16-bit unsigned or float samples, got {data.dtype}")
    white = 1.0 if bits is None else float((1 << bits) - 1)
    if photometric == ph.MINISWHITE:
        data = white - data.astype(np.float64)
    return data, bits, white, samples in (2, 4)


def raw_preview(raw: np.ndarray, cfa: str, black_level: float, white_level: float) -> np.ndarray:
    """Half-size sRGB preview ``(H/2, W/2, 3)`` uint8 of a Bayer mosaic ``(H, W)`` (2x2 binning, gamma 2.2)."""
    raw = np.asarray(raw, dtype=np.float64) - black_level
    colour = tables.cfa_colour_index(cfa, 2, 2)
    planes = {0: [], 1: [], 2: []}
    for dy in range(2):
        for dx in range(2):
            planes[int(colour[dy, dx])].append(raw[dy::2, dx::2])
    rgb = np.stack([planes[0][0], np.mean(planes[2], axis=0), planes[1][0]], axis=-1)
    rgb = np.clip(rgb / max(white_level - black_level, 1e-9) / 0.8, 0, 1) ** (1 / 2.2)
    return (rgb * 255 + 0.5).astype(np.uint8)


def colour_ramp(values: np.ndarray, low: float | None = None, high: float | None = None) -> np.ndarray:
    """Map ``(H, W)`` values to an RGB ramp (dark blue -> cyan -> yellow -> red) ``(H, W, 3)`` uint8; NaN black."""
    v = np.asarray(values, dtype=np.float64)
    finite = np.isfinite(v)
    low = np.nanmin(v[finite]) if low is None and finite.any() else (low or 0.0)
    high = np.nanmax(v[finite]) if high is None and finite.any() else (high or 1.0)
    t = np.where(finite, np.clip((v - low) / max(high - low, 1e-12), 0, 1), 0.0)
    stops = np.array([[0.05, 0.05, 0.35], [0.0, 0.7, 0.9], [0.95, 0.9, 0.1], [0.85, 0.1, 0.05]])
    pos = t * (len(stops) - 1)
    i = np.minimum(np.floor(pos).astype(int), len(stops) - 2)
    f = (pos - i)[..., None]
    rgb = stops[i] * (1 - f) + stops[i + 1] * f
    rgb[~finite] = 0.0
    return (rgb * 255 + 0.5).astype(np.uint8)


def save_png(path, image: np.ndarray) -> Path:
    """Write an ``(H, W)`` or ``(H, W, 3|4)`` uint8 image as PNG; creates the parent folder."""
    from PIL import Image  # noqa: PLC0415 - Pillow comes with scikit-image

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.asarray(image, dtype=np.uint8)).save(path)
    return path
