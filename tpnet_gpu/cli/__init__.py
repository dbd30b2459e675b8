"""The ``tpnet`` command line. Each subcommand has ``--help``; bad input ends with a one-line message, not a
traceback (exit status 2). ``demo``, ``process`` and ``render`` write their output folder whole or not at all and
refuse a non-empty one without ``--overwrite`` (``tpnet_gpu.outputs``)."""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
import sys
import time
from pathlib import Path

# A one-shot run of a frame of at most this many pixels is start-up bound (docs/platform.md §4): the Warp backend
# starts ~1 CPU-second sooner than Taichi and runs such a frame as fast, and torch's second thread only waits.
SMALL_FRAME_PIXELS = 320 * 240
RENDER_MIN_SIDE = 24  # the smallest multiple of 8 that rawio.LIBRAW_MIN_SIDE allows in a DNG


@contextlib.contextmanager
def _one_shot(height: int, width: int, backend: str | None):
    """The backend for one frame of ``height`` x ``width`` (``backend`` if given; "warp" for a small frame; else
    None, the library's default) and, for a small frame, torch on one thread while it runs (restored after)."""
    if height * width > SMALL_FRAME_PIXELS:
        yield backend
        return
    import torch  # noqa: PLC0415 - the pipeline imports it anyway

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield backend or "warp"
    finally:
        torch.set_num_threads(threads)


def _cmd_demo(args: argparse.Namespace) -> int:
    from tpnet_gpu.demo import run_demo

    with _one_shot(args.height, args.width, args.backend) as backend:
        report = run_demo(args.out, width=args.width, height=args.height, seed=args.seed, device=args.device,
                          backend=backend, weights=args.weights, figures=not args.no_figures, overwrite=args.overwrite)
    print(report["text"])
    return 0


def _disparity(text: str | None, option: str, *, positive: bool) -> float | None:
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


def _cmd_process(args: argparse.Namespace) -> int:
    if args.ray or args.address is not None or args.workers is not None:  # scene folders on Ray (cli_ray.py)
        from tpnet_gpu.cli.ray import process_scenes  # noqa: PLC0415

        return process_scenes(args)
    from tpnet_gpu.runtime.progress import Steps

    with Steps(4, desc="process", logger=logging.getLogger("tpnet_gpu.cli")) as step:
        return _process(args, step)


def _process(args: argparse.Namespace, step) -> int:
    from tpnet_gpu.outputs import frame_outputs
    from tpnet_gpu.outputs import check, output_folder
    from tpnet_gpu.io.stereo_io import load_inputs, make_pipeline

    max_d = _disparity(args.max_disparity, "--max-disparity", positive=True)
    min_d = _disparity(args.min_disparity, "--min-disparity", positive=False)
    if max_d is not None and min_d >= max_d:
        raise ValueError(f"--min-disparity: expected less than --max-disparity {max_d:g}, got {min_d:g}")
    out = check(args.out, overwrite=args.overwrite, inputs=args.inputs)  # before the work, not after it
    step("reading the inputs")
    inputs = load_inputs(args.inputs, rig=args.rig, cfa=args.cfa, colour=args.colour, reference=args.reference)
    if inputs.kind in ("pair", "images") and max_d is None:
        raise ValueError("--max-disparity: required for ordinary images (the largest disparity searched, px)")
    frames = inputs.frames
    (height, width), (h, w) = frames.padded, frames.size
    step("pipeline set-up")
    start = time.perf_counter()
    with _one_shot(height, width, args.backend) as backend:
        pipeline = make_pipeline(height, width, cfa=frames.cfa, rig=inputs.rig, min_disparity=min_d,
                                 max_disparity=max_d, weights=args.weights, device=args.device, backend=backend,
                                 two_surface=args.two_surface, cross_check=False if args.no_checks else None,
                                 min_confidence=args.min_confidence, keep_fraction=args.keep_fraction,
                                 per_pixel=True if args.per_pixel else None, method=args.method)
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


def _cmd_render(args: argparse.Namespace) -> int:
    import numpy as np

    from tpnet_gpu.camera import Rig
    from tpnet_gpu.outputs import check, output_folder
    from tpnet_gpu.runtime.progress import Steps
    from tpnet_gpu.scenes import Optics, Sensor, demo_scene, random_scene, render
    from tpnet_gpu.scenes.folder import save

    out = check(args.out, overwrite=args.overwrite, option="out")  # before the work, not after it
    for option, value in (("--width", args.width), ("--height", args.height)):
        if value % 8 or value < RENDER_MIN_SIDE:
            raise ValueError(f"{option}: expected a multiple of 8 that is at least {RENDER_MIN_SIDE} (LibRaw reads "
                             f"no smaller raw), got {value}")
    rig = Rig(width=args.width, height=args.height)
    scene = demo_scene(rig, seed=args.seed) if args.scene == "demo" else random_scene(rig, np.random.default_rng(args.seed))
    optics = Optics()
    sensor = Sensor(bits=args.bits)
    start = time.perf_counter()
    with Steps(rig.cams, desc="render", logger=logging.getLogger("tpnet_gpu.cli")) as step:
        rendered = render(scene, rig, optics=optics, sensor=sensor, supersample=args.supersample, seed=args.seed,
                          noise=not args.no_noise, progress=lambda m: step(f"rendering {m}"))
    seconds = time.perf_counter() - start
    with output_folder(out, overwrite=args.overwrite, option="out") as folder:
        save(rendered, folder, name=f"{args.scene}-{args.seed}", optics=optics)
    print(f"rendered {args.scene} scene (seed {args.seed}), {rig.cams} cameras of {rig.width}x{rig.height}, "
          f"supersample {args.supersample}, in {seconds:.1f} s -> {out}")
    return 0


def _cmd_inspect(args: argparse.Namespace) -> int:
    import numpy as np

    from tpnet_gpu.scenes.folder import load

    scene = load(args.folder)
    cams, height, width = scene.frames.shape
    print(f"{scene.folder}: {cams} cameras, {width}x{height}, CFA {scene.cfa} (read through rawpy)")
    for cam in range(cams):
        f = scene.frames[cam]
        print(f"  camera {cam}: black-subtracted raw min {f.min():.0f}, mean {f.mean():.1f}, max {f.max():.0f}")
    for name, value in sorted(scene.ground_truth.items()):
        v = np.asarray(value, dtype=np.float64)
        print(f"  ground truth {name}: shape {v.shape}, range {np.nanmin(v):.3f} .. {np.nanmax(v):.3f}")
    print(f"  rig: baseline {scene.rig.baseline_mm} mm, focal {scene.rig.focal_mm} mm, pixel {scene.rig.pixel_size_mm} mm")
    return 0


def _cmd_dataset(args: argparse.Namespace) -> int:
    from tpnet_gpu.training.dataset import DatasetSpec, build

    if args.scenes < 1:  # before any folder is made: zero scenes would be an empty data set, not an error
        raise ValueError(f"--scenes: expected at least 1 scene, got {args.scenes}")
    rig = None
    if args.rig is not None:
        from tpnet_gpu.io import rigfile  # noqa: PLC0415

        rig = rigfile.rig_to_dict(rigfile.load(args.rig))
    if args.photo and not args.mono:
        raise ValueError("--photo: finishes mono frames as photographs; expected --mono with it")
    colour = {"cfa": None, "colour_weights": (1.0,), "photo": args.photo} if args.mono else {}
    spec = DatasetSpec(scenes=args.scenes, width=args.width, height=args.height, test_fraction=args.test_fraction,
                       seed=args.seed, supersample=args.supersample, rig=rig, **colour)
    start = time.perf_counter()
    from tpnet_gpu.cli.ray import options  # noqa: PLC0415
    from tpnet_gpu.training.ray_jobs import chunk_builder  # noqa: PLC0415

    ray = options(args)
    folder = build(args.out, spec, device=args.device, chunks=None if ray is None else chunk_builder(ray))
    print(f"data set of {spec.scenes} scenes ({spec.width}x{spec.height}) in {time.perf_counter() - start:.0f} s "
          f"-> {folder}")
    return 0


def _cmd_train(args: argparse.Namespace) -> int:
    import torch

    from tpnet_gpu.net.train import TrainConfig, train

    torch.set_num_threads(args.threads)
    config = TrainConfig(epochs=args.epochs, batch=args.batch, seed=args.seed, w_mode=args.w_mode,
                         error_scale=args.error_scale or None,
                         variant_weights=tuple(args.random_weight if v == "random" else 1.0 for v in TrainConfig.variants),
                         init=args.init, lr_from=args.lr_from, pass_every=args.pass_every)
    device = args.device or ("cuda" if torch.cuda.is_available() else "cpu")
    rig = None
    if args.rig is not None:
        from tpnet_gpu.io import rigfile  # noqa: PLC0415

        rig = rigfile.load(args.rig)
    result = train(args.data, args.out, config, checkpoint=args.checkpoint, device=device, rig=rig)
    last = result["history"][-1]
    print(f"trained {last['epoch']} epochs: loss {last['loss']:.5f}, test RMSE network {last['test_rmse_network']:.4f} "
          f"px vs its targets {last['test_rmse_target']:.4f} px -> {args.out}")
    return 0


BACKEND_HELP = (f"tile-processor kernels (default: warp for frames of at most {SMALL_FRAME_PIXELS} pixels, whose "
                "start-up dominates; else taichi on the CPU, warp on CUDA)")
OVERWRITE_HELP = "replace the files of a non-empty output folder (default: refuse it)"
WEIGHTS_HELP = ("TPNET weights from `tpnet train` (default: the shipped ones for the rig); weights trained for another "
                "rig or other colours are refused")
NO_FIGURES_HELP = "write no labelled figures (PNG, matplotlib): faster; the TIFFs, points.ply and texture.png stay"
BENCHES = ("tp", "accuracy", "network", "network_limits", "network_context", "throughput", "startup", "fuzz",
           "calibration", "ray", "flow", "two_surface", "real", "rendered_pairs")


def _cmd_bench(args: argparse.Namespace) -> int:
    import importlib

    from tpnet_gpu.bench import common

    # tpnet_gpu.bench.bench_NAME.main(args): its --help, a bad option or a missing optional dependency (the
    # ``bench`` extra) end with argparse's status or a one-line message (common.run), not a traceback.
    module = importlib.import_module(f"tpnet_gpu.bench.bench_{args.name}")
    return common.run(module.main, args.args)


def build_parser() -> argparse.ArgumentParser:
    from tpnet_gpu.config import BACKENDS, METHODS, DatasetSpec, TrainConfig  # noqa: PLC0415 - light: numpy only

    spec, train = DatasetSpec(), TrainConfig()
    parser = argparse.ArgumentParser(prog="tpnet", description=__doc__)
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="log what the library does: -v INFO, -vv DEBUG (before the subcommand; stderr)")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="the built-in rendered scene through the pipeline: pictures + report")
    demo.add_argument("--out", default="out/demo", help="output folder")
    demo.add_argument("--width", type=int, default=640, help="frame width, pixels (multiple of 8)")
    demo.add_argument("--height", type=int, default=480, help="frame height, pixels (multiple of 8)")
    demo.add_argument("--seed", type=int, default=0, help="seed of the scene and the noise")
    demo.add_argument("--device", default=None, help="cpu or cuda (default: cuda when present)")
    demo.add_argument("--backend", choices=BACKENDS, default=None, help=BACKEND_HELP)
    demo.add_argument("--weights", default=None, metavar="FILE", help=WEIGHTS_HELP)
    demo.add_argument("--no-figures", action="store_true", help=NO_FIGURES_HELP)
    demo.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    demo.set_defaults(func=_cmd_demo)

    proc = sub.add_parser("process", help="disparity, confidence and texture of a frame: scene folder, raw quad, "
                          "stereo pair, or the cameras of a rig file",
                          description="Inputs: a scene folder; CAM0 CAM1 CAM2 CAM3 raw files (the quad); LEFT RIGHT "
                                      "ordinary images (a rectified stereo pair, PNG/TIFF; needs --max-disparity); or, "
                                      "with --rig, one raw file or image per camera of the rig. Outputs are cropped "
                                      "to the inputs' size (tiles: ceil(size / 8)). See docs/rig_file.md; the "
                                      "output files (depth, points.ply, figures): docs/outputs.md.")
    proc.add_argument("inputs", nargs="+",
                      help="SCENE_DIR | CAM0 CAM1 CAM2 CAM3 | LEFT RIGHT | one file per rig camera")
    proc.add_argument("--rig", default=None, metavar="FILE",
                      help="rig file (.json/.toml, docs/rig_file.md) or a shipped one: quad, binocular, two_quads")
    proc.add_argument("--max-disparity", default=None, metavar="PX",
                      help="largest disparity searched, pixels (> 0); required for ordinary images")
    proc.add_argument("--min-disparity", default="0", metavar="PX",
                      help="smallest disparity searched, pixels (default 0; less than the maximum)")
    proc.add_argument("--colour", choices=("luma", "mean", "green"), default="luma",
                      help="RGB images to mono: BT.601 luma (0.299 R + 0.587 G + 0.114 B), the mean, or green")
    proc.add_argument("--reference", default="auto", metavar="CAM",
                      help="camera the tile grid follows: a camera index, 'rig' (the rig's own reference, its "
                           "virtual centre camera), or 'auto' (camera 0 = left for a stereo pair, else 'rig')")
    proc.add_argument("--out", default="out/process", help="output folder")
    proc.add_argument("--cfa", default=None, help="Bayer pattern of TIFF mosaics (e.g. GRBG); without it TIFFs of a "
                      "rig are read as ordinary images")
    proc.add_argument("--device", default=None, help="cpu or cuda (default: cuda when present)")
    proc.add_argument("--backend", choices=BACKENDS, default=None, help=BACKEND_HELP)
    proc.add_argument("--weights", default=None, metavar="FILE", help=WEIGHTS_HELP)
    proc.add_argument("--method", choices=METHODS, default="auto",
                      help="auto: the disparity engine, then TPNET where weights shipped for default use fit the rig "
                           "and frames (default); tpnet: also weights shipped on request (mono image pairs: they do "
                           "not beat the engine on real photographs, docs/results.md §3); engine: the engine alone")
    proc.add_argument("--no-figures", action="store_true", help=NO_FIGURES_HELP)
    proc.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP + "; never an input's folder")
    proc.add_argument("--two-surface", action="store_true", help="also foreground.tif, background.tif and "
                      "w_foreground.tif: both disparities of tiles whose correlation shows two surfaces (NaN: one)")
    proc.add_argument("--min-confidence", type=float, default=0.0, metavar="C",
                      help="tiles of confidence below C (>= 0; confidence.tif) get no value (default 0: keep all)")
    proc.add_argument("--keep-fraction", type=float, default=1.0, metavar="F",
                      help="keep only the F (0..1] most confident answers (default 1)")
    proc.add_argument("--no-checks", action="store_true", help="answer every tile: no cross-check of a stereo "
                      "pair and no off-image check (docs/outputs.md §1.3)")
    proc.add_argument("--per-pixel", action="store_true",
                      help="also depth_px.tif and points_px.ply, one value per pixel (mono stereo pairs)")
    proc.set_defaults(func=_cmd_process)

    rend = sub.add_parser("render", help="render a synthetic quad-camera scene folder (DNGs + ground truth)")
    rend.add_argument("out", help="output folder")
    rend.add_argument("--scene", choices=("demo", "random"), default="demo", help="built-in scene kind")
    rend.add_argument("--seed", type=int, default=0, help="seed of the scene and the sensor noise")
    rend.add_argument("--width", type=int, default=2592, help="sensor width, pixels (multiple of 8)")
    rend.add_argument("--height", type=int, default=1936, help="sensor height, pixels (multiple of 8)")
    rend.add_argument("--supersample", type=int, default=2, help="sub-pixel rays per axis")
    rend.add_argument("--bits", type=int, default=12, choices=(10, 12, 14, 16), help="sensor bit depth")
    rend.add_argument("--no-noise", action="store_true", help="no photon or read noise")
    rend.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    rend.set_defaults(func=_cmd_render)

    insp = sub.add_parser("inspect", help="read a scene folder back (rawpy) and summarise it")
    insp.add_argument("folder", help="scene folder (cam*.dng + scene.json)")
    insp.set_defaults(func=_cmd_inspect)

    data = sub.add_parser("dataset", help="build a training/test set from rendered random scenes")
    data.add_argument("out", help="output folder (existing scene chunks are kept: the build resumes)")
    data.add_argument("--scenes", type=int, default=spec.scenes, help="number of scenes")
    data.add_argument("--width", type=int, default=spec.width, help="frame width, pixels (multiple of 8)")
    data.add_argument("--height", type=int, default=spec.height, help="frame height, pixels (multiple of 8)")
    data.add_argument("--test-fraction", type=float, default=spec.test_fraction,
                      help="share of scenes held out for testing")
    data.add_argument("--seed", type=int, default=spec.seed, help="seed of the scenes and the split")
    data.add_argument("--supersample", type=int, default=spec.supersample, help="sub-pixel rays per axis")
    data.add_argument("--rig", default=None, metavar="FILE",
                      help="render the scenes with this rig (a rig file, docs/rig_file.md, or a shipped one: quad, "
                           "binocular, two_quads; default the quad); its layers are one per direction group")
    data.add_argument("--mono", action="store_true",
                      help="mono cameras (grey frames, as `tpnet process LEFT.png RIGHT.png` reads images): weights "
                           "trained on it run on image pairs; default Bayer raw frames")
    data.add_argument("--photo", action="store_true",
                      help="with --mono: frames made like ordinary 8-bit photographs (a random lens per scene; per "
                           "camera a random gain, tone curve, blur and JPEG)")
    data.add_argument("--device", default=None, help="cpu or cuda (default: cuda when present)")
    data.set_defaults(func=_cmd_dataset)

    tr = sub.add_parser("train", help="train TPNET on a data set (checkpoints resume)")
    tr.add_argument("data", help="data set folder (from `tpnet dataset`)")
    tr.add_argument("--out", default="out/tpnet.pt", help="final weights (a recipe .json is written beside)")
    tr.add_argument("--rig", default=None, metavar="FILE",
                    help="the rig to train for (a rig file or a shipped one): must be the data set's rig (its layer "
                         "lags); the network always has one layer per direction group of the data set's rig")
    tr.add_argument("--checkpoint", default="out/tpnet_checkpoint.pt", help="checkpoint file (resumed if present)")
    tr.add_argument("--epochs", type=int, default=train.epochs)
    tr.add_argument("--batch", type=int, default=train.batch, help="frames per step")
    tr.add_argument("--seed", type=int, default=train.seed)
    tr.add_argument("--w-mode", choices=("as_coded", "isotropic"), default=train.w_mode,
                    help="Laplacian regulariser of the first layer (network.md §2)")
    tr.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    tr.add_argument("--device", default=None, help="cpu or cuda (default: cuda when present)")
    tr.add_argument("--error-scale", type=float, default=train.error_scale,
                    help="c (px): errors are scaled by c / (|target - gt| + c); 0: plain errors, as the original")
    tr.add_argument("--random-weight", type=float, default=1.0,
                    help="loss weight of the random-offset (+-2 px) targets relative to the others")
    tr.add_argument("--init", default=None, metavar="WEIGHTS",
                    help="fine-tune: start from these weights (e.g. the shipped ones) instead of fresh ones")
    tr.add_argument("--lr-from", type=float, default=train.lr_from,
                    help="fraction of the learning-rate schedule the run starts at (fine-tuning: 0.3, from 3e-5)")
    tr.add_argument("--pass-every", type=int, default=train.pass_every, metavar="EPOCHS",
                    help="train on the network's own pass too: its prediction from the heuristic targets, re-measured "
                         "from the scenes' raw frames every EPOCHS epochs (a second pass converges instead of drifting)")
    tr.set_defaults(func=_cmd_train)

    bench = sub.add_parser("bench", help="run a benchmark of tpnet_gpu.bench (table + JSON)",
                           description="Runs tpnet_gpu.bench.bench_NAME (also `python -m tpnet_gpu.bench.bench_NAME`) "
                                       "with the remaining arguments, e.g. `tpnet bench tp --height 480 --width 640`.")
    bench.add_argument("name", choices=BENCHES, help="which benchmark")
    bench.add_argument("args", nargs=argparse.REMAINDER,
                       help="arguments for the benchmark (see `tpnet bench NAME --help`)")
    bench.set_defaults(func=_cmd_bench)

    from tpnet_gpu.cli import calibrate as cli_calibrate  # noqa: PLC0415 - subcommands and options in
    from tpnet_gpu.cli import export as cli_export
    from tpnet_gpu.cli import flow as cli_flow
    from tpnet_gpu.cli import ray as cli_ray
    # their own modules

    for module in (cli_calibrate, cli_flow, cli_export):
        module.add_parser(sub)
    cli_ray.add_options(proc, data)
    return parser


def main(argv: list[str] | None = None) -> int:
    from tpnet_gpu.runtime.progress import verbosity  # noqa: PLC0415

    args = build_parser().parse_args(argv)
    try:
        with verbosity(args.verbose):
            return args.func(args)
    # the library refuses bad input with ValueError (RawFormatError is one) and files with OSError; a TypeError
    # here would be a bug of ours (the CLI builds every value it passes), so it keeps its traceback (issue 16)
    except (ValueError, OSError) as exc:
        print(f"tpnet {args.command}: error: {exc}", file=sys.stderr)
        return 2
