"""The inputs of ``tpnet process`` as frames for the pipeline (rig_file.md §6-§8): ordinary images (a stereo
pair, or one image per camera of a rig file) and raw files or scene folders, padded to the tile grid, with their
rig; and the one place that builds the pipeline for them (``make_pipeline``).

Frames are ``(cams, H', W')`` float32 in the inputs' own units (no scaling): ordinary images as stored (their
white level 255, 65535 or 1.0 is recorded), raw frames black-subtracted. Sides are padded at the bottom and the
right, by replicating the last row / column (the last 2x2 cell of a Bayer mosaic), to the next multiple of 8 and
at least 16, so pixel and tile coordinates are the originals'; ``Frames.crop_tiles`` / ``crop_image`` cut the
outputs back to the original size.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from tpnet_gpu import tables
from tpnet_gpu.camera import Rig
from tpnet_gpu.io.images import ImageData, read_image
from tpnet_gpu.layout import TILE_SIZE, TILE_STRIDE

COLOURS = ("luma", "mean", "green")
LUMA_WEIGHTS = (0.299, 0.587, 0.114)  # R, G, B: ITU-R BT.601 luma, as Pillow's convert("L"), on the stored values
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".ppm", ".pgm", ".pnm", ".webp")
TIFF_SUFFIXES = (".tif", ".tiff")  # an ordinary image, or a Bayer mosaic when a CFA is given
PAIR_RIG = "binocular"  # shipped rig of a stereo pair given without --rig


def padded_side(n: int) -> int:
    """The tile grid's side for ``n`` pixels: the next multiple of 8, at least 16."""
    return max(TILE_SIZE, -(-int(n) // TILE_STRIDE) * TILE_STRIDE)


def pad_frames(frames: np.ndarray, period: int = 1) -> np.ndarray:
    """``(cams, h, w)`` -> ``(cams, H', W')`` padded at the bottom and the right with copies of the last ``period``
    rows / columns (1: edge replication; 2: a Bayer mosaic keeps its CFA). Returns ``frames`` when no padding
    is needed."""
    _, h, w = frames.shape
    shape = (padded_side(h), padded_side(w))
    if shape == (h, w):
        return frames

    def index(n: int, size: int) -> np.ndarray:
        i = np.arange(size)
        return np.where(i < n, i, n - period + (i - n) % period)

    return frames[:, index(h, shape[0])[:, None], index(w, shape[1])[None, :]]


@dataclass(frozen=True, eq=False)
class Frames:
    """Padded frames and what is needed to crop results back.

    Attributes:
        frames: ``(cams, H', W')`` float32, H' and W' multiples of 8 (at least 16); finite.
        size: ``(h, w)`` of the inputs before padding.
        white_level: saturation in the frames' units (255, 65535 or 1.0 for images; white minus black for raws).
        bits: the samples' bit depth (None for float images; the raw container's for raws).
        cfa: Bayer pattern of raw frames, None for mono frames from ordinary images.
        sources: the input files.
    """

    frames: np.ndarray
    size: tuple[int, int]
    white_level: float
    bits: int | None
    cfa: str | None
    sources: tuple[str, ...]

    @property
    def cams(self) -> int:
        return self.frames.shape[0]

    @property
    def padded(self) -> tuple[int, int]:
        return self.frames.shape[1], self.frames.shape[2]

    @property
    def tiles(self) -> tuple[int, int]:
        """``(tiles_y, tiles_x)`` covering the original size: ceil(h / 8), ceil(w / 8)."""
        return -(-self.size[0] // TILE_STRIDE), -(-self.size[1] // TILE_STRIDE)

    def crop_tiles(self, tiles):
        """A tile map ``(..., H'/8, W'/8)`` cut to ``(..., ceil(h/8), ceil(w/8))``."""
        ty, tx = self.tiles
        return tiles[..., :ty, :tx]

    def crop_image(self, image):
        """An image ``(..., H', W')`` cut to ``(..., h, w)``."""
        return image[..., : self.size[0], : self.size[1]]


def to_mono(image: ImageData, colour: str = "luma") -> np.ndarray:
    """``(H, W)`` float32 of a grey or RGB image: grey as is; RGB by ``colour``: "luma" (``LUMA_WEIGHTS``),
    "mean" of R, G, B, or "green"."""
    if colour not in COLOURS:
        raise ValueError(f"colour: expected one of {COLOURS}, got {colour!r}")
    data = image.data
    if data.ndim == 2:
        return data
    if colour == "green":
        return np.ascontiguousarray(data[..., 1])
    weights = LUMA_WEIGHTS if colour == "luma" else (1 / 3, 1 / 3, 1 / 3)
    return np.tensordot(data.astype(np.float64), np.asarray(weights), axes=([2], [0])).astype(np.float32)


def load_images(paths, *, colour: str = "luma", names=None) -> Frames:
    """One ordinary image per camera (``read_image``) as padded mono frames.

    Args:
        paths: the image files, in camera order.
        colour: how RGB becomes mono (``to_mono``).
        names: what to call each argument in messages (default "image 0", "image 1", ...).

    Raises:
        ValueError: no paths, a bad ``colour``, images of different sizes or white levels (both named).
        FileNotFoundError, ImageFormatError: from ``read_image``.
    """
    paths = list(paths)
    if not paths:
        raise ValueError("paths: expected at least one image, got none")
    if colour not in COLOURS:
        raise ValueError(f"colour: expected one of {COLOURS}, got {colour!r}")
    names = [f"image {i}" for i in range(len(paths))] if names is None else list(names)
    images = [read_image(p, name=n) for p, n in zip(paths, names, strict=True)]
    first = images[0]
    for name, image in zip(names[1:], images[1:]):
        if image.data.shape[:2] != first.data.shape[:2]:
            raise ValueError(f"{names[0]} and {name}: expected the same size, got {first.width}x{first.height} "
                             f"({first.source}) and {image.width}x{image.height} ({image.source})")
        if image.white_level != first.white_level:
            raise ValueError(f"{names[0]} and {name}: expected the same bit depth, got white level "
                             f"{first.white_level:g} ({first.source}) and {image.white_level:g} ({image.source})")
    frames = np.stack([to_mono(image, colour) for image in images])
    return Frames(pad_frames(frames), frames.shape[1:], first.white_level, first.bits, None,
                  tuple(image.source for image in images))


def load_stereo_pair(left, right, *, colour: str = "luma") -> Frames:
    """A rectified stereo pair of ordinary images (PNG/TIFF, 8/16-bit, grey or RGB(A)) as ``Frames`` of 2 mono
    frames (left = camera 0), padded; RGB becomes mono by ``colour`` (default luma, ``LUMA_WEIGHTS``).

    Raises:
        FileNotFoundError, ImageFormatError, ValueError: as ``load_images``, naming "left" / "right".
    """
    return load_images([left, right], colour=colour, names=("left", "right"))


def _raw_bits(white: float) -> int | None:
    """Bit depth of integer raw samples from their white level (4095 -> 12); None for float mosaics."""
    return int(white).bit_length() if white >= 1 and white == int(white) else None


def _raw_frames(paths, cfa: str | None) -> Frames:
    from tpnet_gpu.io import rawio  # noqa: PLC0415 - rawpy on use

    frames = rawio.read_frames(paths, cfa=cfa)
    stack = rawio.stack_normalised(frames)
    first = frames[0]
    return Frames(pad_frames(stack, period=2), stack.shape[1:], first.white_level - float(first.black_level.mean()),
                  _raw_bits(first.white_level), first.cfa, tuple(f.source for f in frames))


def _scene_frames(folder: Path) -> tuple[Frames, Rig]:
    from tpnet_gpu.io import rawio  # noqa: PLC0415
    from tpnet_gpu.scenes.folder import load  # noqa: PLC0415

    scene = load(folder)
    meta = json.loads((folder / rawio.SCENE_JSON).read_text())  # the levels (load checked the file)
    white = float(meta.get("white_level", float("nan")))
    black = float(np.mean(meta.get("black_level", 0.0)))
    frames = Frames(pad_frames(scene.frames, period=2), scene.frames.shape[1:], white - black, _raw_bits(white),
                    scene.cfa, (str(folder),))
    return frames, scene.rig


def _is_raw(path: Path, cfa: str | None) -> bool:
    suffix = path.suffix.lower()
    if suffix in TIFF_SUFFIXES:
        return cfa is not None
    return suffix not in IMAGE_SUFFIXES


def fit_rig(rig: Rig, frames: Frames, what: str = "rig") -> Rig:
    """``rig`` for the padded frames: its camera count must match; an ideal rig takes the frames' padded size,
    a non-ideal one (distortion, corrections, rolls, principal points) must describe the frames' size, and
    that size must need no padding (its virtual camera is centred on the sensor)."""
    if rig.cams != frames.cams:
        raise ValueError(f"{what}: describes {rig.cams} cameras, got {frames.cams} inputs")
    (h, w), (hp, wp) = frames.size, frames.padded
    if rig.is_ideal():
        return replace(rig, width=wp, height=hp, _cache={})
    if (rig.height, rig.width) != (h, w):
        raise ValueError(f"{what}: describes sensors of {rig.width}x{rig.height}, the inputs are {w}x{h}")
    if (hp, wp) != (h, w):
        raise ValueError(f"{what}: a rig with distortion or corrections needs inputs whose sides are multiples "
                         f"of {TILE_STRIDE} (at least {TILE_SIZE}), got {w}x{h}")
    return rig


@dataclass(frozen=True, eq=False)
class Inputs:
    """What ``load_inputs`` made of the ``process`` inputs: ``frames``, the ``rig`` fitted to them (and
    re-referenced), and ``kind``: "scene", "pair" (two ordinary images), "images" or "raw"."""

    frames: Frames
    rig: Rig
    kind: str


def _reference(rig: Rig, reference, kind: str) -> Rig:
    if reference == "auto":
        return rig.referenced_to(0) if kind == "pair" else rig
    if reference == "rig":
        return rig
    try:
        cam = int(reference)
    except (TypeError, ValueError):
        raise ValueError(f"reference: expected 'auto', 'rig' or a camera index, got {reference!r}") from None
    try:
        return rig.referenced_to(cam)
    except ValueError as exc:
        raise ValueError(f"reference: {exc}") from None


def load_inputs(paths, *, rig=None, cfa: str | None = None, colour: str = "luma", reference="auto") -> Inputs:
    """The inputs of ``tpnet process`` (rig_file.md §8) as padded frames and their rig.

    Without ``rig``: one scene folder (its own rig), two ordinary images whatever their names (a stereo pair:
    the shipped binocular rig), or four raw files (the ideal quad). With ``rig`` (a ``Rig``, a rig file or a
    shipped example's name): one input per camera, all ordinary images (PNG, ..., or TIFF without ``cfa``) or
    all raw files (DNG, ..., or TIFF mosaics with ``cfa``). ``reference``: "auto" (camera 0 for a stereo pair of
    images, otherwise the rig as given), "rig" (as given) or a camera index (``Rig.referenced_to``).

    Raises:
        ValueError: a count or kind of inputs that fits none of these (the message says what would), a rig that
            does not fit them; FileNotFoundError, ImageFormatError, RawFormatError, RigFileError from reading.
    """
    from tpnet_gpu.io import rigfile  # noqa: PLC0415

    paths = [Path(p) for p in ([paths] if isinstance(paths, (str, Path)) else paths)]
    count = len(paths)
    if rig is not None and not isinstance(rig, Rig):
        rig = rigfile.load(rig)
    if count == 1 and paths[0].is_dir():
        if rig is not None:
            raise ValueError(f"rig: a scene folder carries its own rig ({paths[0]}/scene.json); drop --rig")
        frames, scene_rig = _scene_frames(paths[0])
        return Inputs(frames, _reference(fit_rig(scene_rig, frames, "scene rig"), reference, "scene"), "scene")
    if count == 1 and not paths[0].exists():
        raise FileNotFoundError(f"inputs: no such scene folder: {paths[0]}")
    raw = [_is_raw(p, cfa) for p in paths]
    if rig is None:
        if count == 2:  # ordinary images whatever their names (read_image says what a raw file is)
            rig, kind = rigfile.load(PAIR_RIG), "pair"
        elif count == 4:
            if not all(raw):
                bad = paths[raw.index(False)]
                raise ValueError(f"inputs: 4 inputs without --rig are a raw quad (DNG, or TIFF mosaics with --cfa), "
                                 f"got the image {bad}; for ordinary images give --rig (e.g. --rig quad)")
            rig, kind = Rig(), "raw"
        else:
            raise ValueError(f"inputs: expected a scene folder, a stereo pair LEFT RIGHT or 4 raw files (one per "
                             f"camera), got {count}; give --rig FILE for other camera counts")
    else:
        if count != rig.cams:
            raise ValueError(f"inputs: the rig has {rig.cams} cameras, got {count} inputs")
        if any(raw) and not all(raw):
            raise ValueError(f"inputs: expected all raw files or all ordinary images, got raw {paths[raw.index(True)]}"
                             f" and image {paths[raw.index(False)]}")
        kind = "raw" if raw[0] else ("pair" if count == 2 else "images")
    if kind == "raw":
        frames = _raw_frames(paths, cfa)
    elif kind == "pair":
        frames = load_stereo_pair(*paths, colour=colour)
    else:
        frames = load_images(paths, colour=colour, names=[f"camera {i}" for i in range(count)])
    return Inputs(frames, _reference(fit_rig(rig, frames), reference, kind), kind)


def make_pipeline(inputs: Inputs, *, min_disparity: float | None = None, max_disparity: float | None = None, weights=None,
                  device: str | None = None, backend: str | None = None, two_surface: bool = False,
                  memory_limit_gb: float | None = None, **answers):
    """The pipeline for ``inputs`` (``load_inputs``: their padded size, colours and fitted rig; any camera count).
    ``min_disparity`` None: the engine's default (0); ``max_disparity`` None: the engine's default from the rig - for a scene or raw files, whose rig is a real
    one; ordinary images (a pair, a rig's images) need it (``ValueError``: their rig's focal length and
    baseline are not known). ``weights`` None: the shipped ones for the rig (``Pipeline``); ``two_surface``:
    also both surfaces of two-surface tiles; ``memory_limit_gb``: ``EngineConfig``'s (None: a share of the memory
    available); ``answers``: ``PipelineConfig``'s ``textures``, ``cross_check``, ``min_confidence``,
    ``keep_fraction``, ``per_pixel``, ``method``."""
    from tpnet_gpu.config import EngineConfig  # noqa: PLC0415
    from tpnet_gpu.pipeline import Pipeline, PipelineConfig  # noqa: PLC0415 - torch, Warp and the model on use

    if inputs.kind in ("pair", "images") and max_disparity is None:
        raise ValueError("max_disparity: required for ordinary images (the largest disparity searched, px)")
    config = PipelineConfig(engine=EngineConfig(memory_limit_gb=memory_limit_gb), two_surface=two_surface, **answers)
    height, width = inputs.frames.padded
    return Pipeline(height, width, cfa=inputs.frames.cfa, rig=inputs.rig, min_disparity=min_disparity,
                    max_disparity=max_disparity, weights=weights, device=device, backend=backend, config=config)


def load_frame(path, *, cfa: str | None = None, colour: str = "luma") -> Frames:
    """One frame of a camera or rig (e.g. of a sequence, ``tpnet flow``): a scene folder (its cameras), a raw
    file (DNG, ..., or a TIFF mosaic with ``cfa``; one Bayer frame) or an ordinary image (mono by ``colour``)."""
    path = Path(path)
    if path.is_dir():
        return _scene_frames(path)[0]
    if not path.exists():
        raise FileNotFoundError(f"path: no such scene folder or file: {path}")
    return _raw_frames([path], cfa) if _is_raw(path, cfa) else load_images([path], colour=colour, names=["frame"])
