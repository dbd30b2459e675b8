"""What the subcommands share: option help texts and the parsing of option values the library cannot see
(a number of pixels given as text)."""

from __future__ import annotations

import argparse
import contextlib
import inspect
import math

from tpnet_gpu.config import ONE_SHOT_PIXELS, SMALL_FRAME_PIXELS

BACKEND_HELP = (f"tile-processor kernels (default: warp for frames of at most {SMALL_FRAME_PIXELS} pixels, whose "
                "start-up dominates, and on CUDA; else taichi)")
ONE_SHOT_BACKEND_HELP = (f"tile-processor kernels (default: warp for one frame of at most {ONE_SHOT_PIXELS} pixels, "
                         "whose start-up dominates, and on CUDA; else taichi - for a video, warp up to "
                         f"{SMALL_FRAME_PIXELS})")
DEVICE_HELP = "cpu or cuda (default: cuda when present)"
OVERWRITE_HELP = "replace the files of a non-empty output folder (default: refuse it)"
WEIGHTS_HELP = ("TPNET weights from `tpnet train` (default: the shipped ones for the rig); weights trained for another "
                "rig or other colours are refused")
NO_FIGURES_HELP = "write no labelled figures (PNG, matplotlib): faster; the TIFFs, points.ply and texture.png stay"


def default(function, name: str):
    """The default of ``function``'s argument ``name``: an option whose value the library also defaults takes the
    library's (one default per setting)."""
    return inspect.signature(function).parameters[name].default


def pixels(text: str | None, option: str, *, positive: bool) -> float | None:
    """A finite number of pixels from an option's text (checked here, so that a bad one is a one-line error)."""
    if text is None:
        return None
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or (positive and value <= 0):
        raise ValueError(f"{option}: expected a {'positive ' if positive else ''}number of pixels, got {text!r}")
    return value


def positive_gb(text: str) -> float:
    """An argparse type: a finite number of GB > 0 (argparse says which option and what came)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"expected a finite number of GB > 0, got {text!r}")
    return value


@contextlib.contextmanager
def one_shot_threads(height: int, width: int):
    """While one frame of ``height`` x ``width`` runs: torch on one thread for a small frame (its second thread
    only waits on a start-up-bound run, docs/platform.md §4), restored after; a larger frame is left alone."""
    if height * width > SMALL_FRAME_PIXELS:
        yield
        return
    import torch  # noqa: PLC0415 - the pipeline imports it anyway

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def one_shot_backend(backend: str | None, height: int, width: int) -> str | None:
    """``backend`` as given, else "warp" for one frame of at most ``ONE_SHOT_PIXELS`` pixels (the process ends
    after it: start-up dominates), else None (the library's choice)."""
    if backend is not None or height * width > ONE_SHOT_PIXELS:
        return backend
    return "warp"


def pipeline_for(args, inputs, min_d: float | None, max_d: float | None, backend: str | None):
    """The ``Pipeline`` that ``tpnet process``'s options ask for, sized by ``inputs`` (``load_inputs``: one
    frame's, or a video's first), on ``backend``; ordinary images without ``--max-disparity`` are refused."""
    from tpnet_gpu.io.stereo_io import make_pipeline  # noqa: PLC0415 - torch and Warp on use

    if inputs.kind in ("pair", "images") and max_d is None:  # the library's rule, said with the option's name
        raise ValueError("--max-disparity: required for ordinary images (the largest disparity searched, px)")
    return make_pipeline(inputs, min_disparity=min_d, max_disparity=max_d, weights=args.weights, device=args.device,
                         backend=backend, two_surface=args.two_surface,
                         cross_check=False if args.no_checks else None, min_confidence=args.min_confidence,
                         keep_fraction=args.keep_fraction, per_pixel=True if args.per_pixel else None,
                         method=args.method, memory_limit_gb=args.memory_limit, textures=not args.no_texture)
