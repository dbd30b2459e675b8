"""``tpnet process``: disparity, confidence and texture of one frame - a scene folder, a raw quad, a stereo pair or
the cameras of a rig file (``tpnet_gpu.io.stereo_io``, ``tpnet_gpu.pipeline``); with ``--ray`` many scene folders
(``cli/ray.py``)."""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

from tpnet_gpu.cli.common import DEVICE_HELP, NO_FIGURES_HELP, ONE_SHOT_BACKEND_HELP, OVERWRITE_HELP, \
    WEIGHTS_HELP, default, one_shot_backend, one_shot_threads, pipeline_for, pixels, positive_gb
from tpnet_gpu.io import sequence, stereo_io  # light: the images are read on use

# the library's defaults of the options that set how the inputs are read (one default per setting)
INPUT_DEFAULTS = {name: default(stereo_io.load_inputs, name) for name in ("colour", "reference")}


def run(args: argparse.Namespace) -> int:
    if args.ray or args.address is not None or args.workers is not None:  # scene folders on Ray (cli/ray.py)
        if sequence.is_sequence(args.inputs):  # before Ray starts: each folder would fail as a scene
            raise ValueError("--ray: processes scene folders (each with its scene.json); these folders have none - a "
                             "video (one folder of frames per camera) runs without --ray")
        from tpnet_gpu.cli.ray import process_scenes  # noqa: PLC0415

        return process_scenes(args)
    from tpnet_gpu.runtime.progress import Steps  # noqa: PLC0415

    with Steps(4, desc="process", logger=logging.getLogger("tpnet_gpu.cli")) as step:
        return _process(args, step)


def _process(args: argparse.Namespace, step) -> int:
    from tpnet_gpu.outputs import claimed  # noqa: PLC0415

    max_d = pixels(args.max_disparity, "--max-disparity", positive=True)
    min_d = pixels(args.min_disparity, "--min-disparity", positive=False)
    if max_d is not None and min_d is not None and min_d >= max_d:
        raise ValueError(f"--min-disparity: expected less than --max-disparity {max_d:g}, got {min_d:g}")
    with claimed(args.out, overwrite=args.overwrite, inputs=args.inputs) as out:  # before the work, not after it
        if sequence.is_sequence(args.inputs):  # one folder of frames per camera: a video (cli/sequence.py)
            from tpnet_gpu.cli.sequence import process_sequence  # noqa: PLC0415

            return process_sequence(args, step, out, min_d, max_d)
        if args.no_follow:
            raise ValueError("--no-follow: only for a video (one folder of frames per camera), got "
                             f"{len(args.inputs)} input(s) of one frame")
        return _claimed(args, step, out, min_d, max_d)


def _claimed(args: argparse.Namespace, step, out: Path, min_d: float | None, max_d: float | None) -> int:
    from tpnet_gpu.io.stereo_io import load_inputs  # noqa: PLC0415 - torch and Warp on use
    from tpnet_gpu.outputs import frame_outputs, output_folder  # noqa: PLC0415

    step("reading the inputs")
    inputs = load_inputs(args.inputs, rig=args.rig, cfa=args.cfa, colour=args.colour, reference=args.reference)
    frames = inputs.frames
    (height, width), (h, w) = frames.padded, frames.size
    step("pipeline set-up")
    start = time.perf_counter()
    with one_shot_threads(height, width):
        pipeline = pipeline_for(args, inputs, min_d, max_d, one_shot_backend(args.backend, height, width))
        step("frame")
        result = pipeline.process(frames.frames)
    seconds = time.perf_counter() - start
    step("outputs" + ("" if args.no_figures else " and figures"))
    maps = frame_outputs.from_result(result, inputs.rig, frames=frames,
                                     white=frames.white_level if inputs.kind in ("pair", "images") else None)
    scene = " ".join(p.name for p in map(Path, args.inputs))
    with output_folder(out, overwrite=args.overwrite, inputs=args.inputs) as folder:
        written = frame_outputs.write(folder, maps, scene=scene, what=frame_outputs.method(pipeline),
                                      figures=not args.no_figures, per_pixel=args.per_pixel)
        if args.two_surface:  # NaN where the tile shows one surface
            written += frame_outputs.write_surfaces(folder, result.surfaces, frames)
    step.close()  # the bar off the terminal before the report
    what = {"scene": "scene", "raw": f"raw ({frames.cfa})", "pair": "stereo pair", "images": "image"}[inputs.kind]
    print(f"processed {w}x{h} {what} frame of {frames.cams} cameras in {seconds:.1f} s -> {out}: {', '.join(written)} "
          f"({maps.disparity.shape[1]}x{maps.disparity.shape[0]} tiles; {frame_outputs.method(pipeline)})")
    return 0


def add_parser(sub) -> argparse.ArgumentParser:
    from tpnet_gpu.config import BACKENDS, METHODS, PipelineConfig  # noqa: PLC0415 - light: numpy only

    proc = sub.add_parser("process", help="disparity, confidence and texture of a frame: scene folder, raw quad, "
                          "stereo pair, or the cameras of a rig file",
                          description="Inputs: a scene folder; CAM0 CAM1 CAM2 CAM3 raw files (the quad); LEFT RIGHT "
                                      "ordinary images (a rectified stereo pair, PNG/TIFF; needs --max-disparity); or, "
                                      "with --rig, one raw file or image per camera of the rig. Outputs are cropped "
                                      "to the inputs' size (tiles: ceil(size / 8)). See docs/rig_file.md; the "
                                      "output files (depth, points.ply, figures): docs/outputs.md.")
    proc.add_argument("inputs", nargs="+",
                      help="SCENE_DIR | CAM0 CAM1 CAM2 CAM3 | LEFT RIGHT | one file per rig camera | a video: one "
                           "folder of frames per camera (LEFT_DIR RIGHT_DIR; frame i = each folder's i-th file)")
    proc.add_argument("--rig", default=None, metavar="FILE",
                      help="rig file (.json/.toml, docs/rig_file.md) or a shipped one: quad, binocular, two_quads")
    proc.add_argument("--max-disparity", default=None, metavar="PX",
                      help="largest disparity searched, pixels (> 0); required for ordinary images")
    proc.add_argument("--min-disparity", default=None, metavar="PX",
                      help="smallest disparity searched, pixels (default 0; less than the maximum)")
    proc.add_argument("--colour", choices=("luma", "mean", "green"), default=INPUT_DEFAULTS["colour"],
                      help="RGB images to mono: BT.601 luma (0.299 R + 0.587 G + 0.114 B), the mean, or green")
    proc.add_argument("--reference", default=INPUT_DEFAULTS["reference"], metavar="CAM",
                      help="camera the tile grid follows: a camera index, 'rig' (the rig's own reference, its "
                           "virtual centre camera), or 'auto' (camera 0 = left for a stereo pair, else 'rig')")
    proc.add_argument("--out", default="out/process", help="output folder")
    proc.add_argument("--cfa", default=None, help="Bayer pattern of TIFF mosaics (e.g. GRBG); without it TIFFs of a "
                      "rig are read as ordinary images")
    proc.add_argument("--device", default=None, help=DEVICE_HELP)
    proc.add_argument("--backend", choices=BACKENDS, default=None, help=ONE_SHOT_BACKEND_HELP)
    proc.add_argument("--weights", default=None, metavar="FILE", help=WEIGHTS_HELP)
    proc.add_argument("--method", choices=METHODS, default=PipelineConfig.method,
                      help="auto: the disparity engine, then TPNET where weights shipped for default use fit the rig "
                           "and frames (default); tpnet: also weights shipped on request (mono image pairs: they do "
                           "not beat the engine on real photographs, docs/results.md §3); engine: the engine alone")
    proc.add_argument("--no-figures", action="store_true", help=NO_FIGURES_HELP)
    proc.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP + "; never an input's folder")
    proc.add_argument("--two-surface", action="store_true", help="also foreground.tif, background.tif and "
                      "w_foreground.tif: both disparities of tiles whose correlation shows two surfaces (NaN: one)")
    proc.add_argument("--min-confidence", type=float, default=PipelineConfig.min_confidence, metavar="C",
                      help="tiles of confidence below C (>= 0; confidence.tif) get no value (default 0: keep all)")
    proc.add_argument("--keep-fraction", type=float, default=PipelineConfig.keep_fraction, metavar="F",
                      help="keep only the F (0..1] most confident answers (default 1)")
    proc.add_argument("--no-checks", action="store_true", help="answer every tile: no cross-check of a stereo "
                      "pair and no off-image check (docs/outputs.md §1.3)")
    proc.add_argument("--memory-limit", type=positive_gb, default=None, metavar="GB",
                      help="the budget of the search's range-sized buffers; a frame and range that need more are "
                           "refused before the work (default: 80 %% of the memory available at the start)")
    proc.add_argument("--no-texture", action="store_true", help="no texture: no texture.tif / texture.png, "
                      "points.ply without colours; the frame skips the texture pass (a quarter of a 5 MPix quad "
                      "frame's time)")
    proc.add_argument("--no-follow", action="store_true", help="a video: search every frame's whole range "
                      "(default: each frame starts from the one before's answers and re-searches only lost tiles)")
    proc.add_argument("--per-pixel", action="store_true",
                      help="also depth_px.tif and points_px.ply, one value per pixel (mono stereo pairs)")
    proc.set_defaults(func=run)
    return proc
