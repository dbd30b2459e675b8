"""``tpnet flow``: per-tile motion vectors between frames (``tpnet_gpu.flow``), two frames or a sequence.

Inputs: two frames ``A B``, more frames in order, or one folder holding a sequence (its scene folders, or else its
raw / image files, in name order). A frame is a scene folder (its cameras' flow combined, aligned by the disparity
engine with the ideal quad of the frame size, so 4 cameras; or ``--camera N``'s), a raw file or an ordinary image
(``stereo_io.load_frame``). Per consecutive pair k the output folder (written whole or not at all,
``tpnet_gpu.outputs``) gets ``flow_k.tif`` (``(2, tiles_y, tiles_x)`` float32: x, y px; NaN where not valid),
``confidence_k.tif``, ``flow_k.png`` (direction as hue, length as brightness) and, unless ``--no-figures``,
``flow_k_figure.png`` (the x and y components, labelled, with colour bars in px; docs/outputs.md §2); k is ``NNNN``
for a sequence and empty for one pair. Each pair starts from the previous pair's flow (a sequence's motion is
smooth).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from tpnet_gpu.io.sequence import frames_in

HELP = "per-tile motion vectors between frames: A B (scene folders, raw files or images) or a sequence folder"


def sequence(inputs: list[str]) -> list[Path]:
    """The frames in order: the inputs themselves, or a single folder's scene folders / raw and image files."""
    paths = [Path(p) for p in inputs]
    if len(paths) >= 2:
        return paths
    folder = paths[0]
    if not folder.is_dir():
        raise ValueError(f"inputs: expected two frames or a sequence folder, got the single file {folder}")
    if (folder / "scene.json").exists():
        raise ValueError(f"inputs: {folder} is one scene folder (one frame); give two frames or a sequence folder")
    scenes = sorted(p for p in folder.iterdir() if p.is_dir() and (p / "scene.json").exists())
    frames = scenes or frames_in(folder)
    if len(frames) < 2:
        raise ValueError(f"inputs: expected a sequence folder of at least 2 scene folders or raw/image files, got "
                         f"{len(frames)} in {folder}")
    return frames


def flow_colours(flow: np.ndarray) -> np.ndarray:
    """``(ty, tx, 2)`` flow -> ``(ty, tx, 3)`` uint8: hue = direction, brightness = length / the longest; NaN black."""
    x, y = flow[..., 0], flow[..., 1]
    length = np.hypot(x, y)
    finite = np.isfinite(length)
    top = float(length[finite].max()) if finite.any() and length[finite].max() > 0 else 1.0
    hue = (np.arctan2(y, x) / (2 * np.pi)) % 1.0 * 6.0
    value = np.where(finite, np.clip(length / top, 0, 1), 0.0)
    k = np.floor(np.nan_to_num(hue)).astype(int) % 6
    f = np.nan_to_num(hue) - np.floor(np.nan_to_num(hue))
    ones, zeros = np.ones_like(f), np.zeros_like(f)
    table = [(ones, f, zeros), (1 - f, ones, zeros), (zeros, ones, f), (zeros, 1 - f, ones), (f, zeros, ones),
             (ones, zeros, 1 - f)]  # HSV at full saturation, by sextant
    rgb = np.zeros((*f.shape, 3))
    for sextant, channels in enumerate(table):
        rgb[k == sextant] = np.stack(channels, axis=-1)[k == sextant]
    return (rgb * value[..., None] * 255 + 0.5).astype(np.uint8)


def _init(text: str | None):
    if text is None:
        return None
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 2 or not all(np.isfinite(values)):
        raise ValueError(f"--init: expected X,Y in pixels (e.g. 3.5,-1), got {text!r}")
    return values


def run(args: argparse.Namespace) -> int:
    from tpnet_gpu.outputs import claimed  # noqa: PLC0415

    paths = sequence(args.inputs)
    init = _init(args.init)
    with claimed(args.out, overwrite=args.overwrite, inputs=paths) as out:  # before the work, not after it
        return _claimed(args, paths, init, out)


def _claimed(args: argparse.Namespace, paths: list, init, out) -> int:
    import tifffile  # noqa: PLC0415 - the command's own imports on use (start-up)

    from tpnet_gpu.flow import FlowEstimator  # noqa: PLC0415
    from tpnet_gpu.io.images import save_png  # noqa: PLC0415
    from tpnet_gpu.io.stereo_io import load_frame  # noqa: PLC0415
    from tpnet_gpu.outputs import output_folder  # noqa: PLC0415

    frames = [load_frame(p, cfa=args.cfa, colour=args.colour) for p in paths]
    first = frames[0]
    for path, f in zip(paths[1:], frames[1:]):
        if f.frames.shape != first.frames.shape or f.cfa != first.cfa:
            raise ValueError(f"inputs: expected frames like {paths[0]} ({first.cams} x {first.size}, cfa "
                             f"{first.cfa}), got {path} ({f.cams} x {f.size}, cfa {f.cfa})")
    if args.camera is not None and not 0 <= args.camera < first.cams:
        raise ValueError(f"--camera: expected a camera index in 0..{first.cams - 1}, got {args.camera}")
    pick = slice(None) if args.camera is None else slice(args.camera, args.camera + 1)
    (height, width), cams = first.padded, len(range(first.cams)[pick])
    start = time.perf_counter()
    estimator = FlowEstimator(height, width, cams=cams, cfa=first.cfa, device=args.device, backend=args.backend)
    results = []
    for a, b in zip(frames[:-1], frames[1:]):
        result = estimator.estimate(a.frames[pick], b.frames[pick], init=init)
        flow = result.flow.cpu().numpy()
        init = np.where(np.isfinite(flow), flow, np.nanmedian(flow, axis=(0, 1)) if np.isfinite(flow).any() else 0)
        results.append((first.crop_tiles(np.moveaxis(flow, -1, 0)), first.crop_tiles(result.confidence.cpu().numpy())))
    seconds = time.perf_counter() - start
    with output_folder(out, overwrite=args.overwrite, inputs=paths) as folder:
        for k, (flow, confidence) in enumerate(results):
            tag = "" if len(results) == 1 else f"_{k:04d}"
            tifffile.imwrite(folder / f"flow{tag}.tif", flow.astype(np.float32), photometric="minisblack")
            tifffile.imwrite(folder / f"confidence{tag}.tif", confidence.astype(np.float32))
            h, w = first.size
            save_png(folder / f"flow{tag}.png", flow_colours(np.moveaxis(flow, 0, -1)).repeat(8, 0).repeat(8, 1)[:h, :w])
            if not args.no_figures:
                _figure(folder / f"flow{tag}_figure.png", flow, (h, w), f"{paths[k].name} -> {paths[k + 1].name}")
    valid = np.mean([np.isfinite(f[0]).mean() for f, _ in results])
    what = "all cameras combined" if args.camera is None and cams > 1 else f"camera {args.camera or 0}"
    print(f"flow of {len(results)} frame pair{'s' if len(results) > 1 else ''} ({first.size[1]}x{first.size[0]}, "
          f"{what}) in {seconds:.1f} s -> {out}: flow*.tif/.png, confidence*.tif ({100 * valid:.0f} % of tiles "
          "valid)")
    return 0


def _figure(path, flow: np.ndarray, size: tuple[int, int], pair: str) -> None:
    """``flow (2, tiles_y, tiles_x)`` px as a labelled figure: its x and y components on one symmetric scale."""
    from tpnet_gpu.outputs.figures import Panel, save  # noqa: PLC0415 - matplotlib on use

    finite = np.abs(flow[np.isfinite(flow)])
    top = max(float(np.percentile(finite, 99)), 1e-3) if finite.size else 1.0
    panels = [Panel(flow[i], f"motion {axis} (+: {sign})", f"flow {axis}", "px", "coolwarm", -top, top)
              for i, (axis, sign) in enumerate((("x", "right"), ("y", "down")))]
    save(path, panels, title=f"tile motion vectors, {pair}", size=size)


def add_parser(sub) -> argparse.ArgumentParser:
    """Register ``tpnet flow`` on the ``tpnet`` subparsers ``sub``."""
    from tpnet_gpu.config import BACKENDS  # noqa: PLC0415 - light: numpy only

    p = sub.add_parser("flow", help=HELP, description=__doc__.split("\n\n", 1)[1])
    p.add_argument("inputs", nargs="+", help="A B [C ...] frames, or one sequence folder")
    p.add_argument("--out", default="out/flow", help="output folder")
    p.add_argument("--camera", type=int, default=None, metavar="N",
                   help="the flow of this camera of multi-camera frames (default: every camera's, combined)")
    p.add_argument("--init", default=None, metavar="X,Y", help="first guess of the flow, px (default 0,0)")
    p.add_argument("--cfa", default=None, help="Bayer pattern of TIFF mosaics (e.g. GRBG)")
    p.add_argument("--colour", choices=("luma", "mean", "green"), default="luma", help="RGB images to mono")
    p.add_argument("--device", default=None, help="cpu or cuda (default: cuda when present)")
    p.add_argument("--backend", choices=BACKENDS, default=None, help="tile-processor kernels: warp or taichi")
    p.add_argument("--overwrite", action="store_true", help="replace the files of a non-empty output folder")
    p.add_argument("--no-figures", action="store_true", help="write no labelled figures (PNG, matplotlib): faster")
    p.set_defaults(func=run)
    return p
