"""``tpnet dataset``: a training / test set from rendered random scenes (``tpnet_gpu.training.dataset``); with
``--ray`` its missing scenes on Ray workers (``cli/ray.py``)."""

from __future__ import annotations

import argparse
import time

from tpnet_gpu.cli.common import DEVICE_HELP


def run(args: argparse.Namespace) -> int:
    from tpnet_gpu.cli.ray import options  # noqa: PLC0415
    from tpnet_gpu.config import DatasetSpec  # noqa: PLC0415
    from tpnet_gpu.training.dataset import build  # noqa: PLC0415
    from tpnet_gpu.training.ray_jobs import chunk_builder  # noqa: PLC0415

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
                       seed=args.seed, supersample=args.supersample, rig=rig, curved=args.curved, **colour)
    start = time.perf_counter()
    ray = options(args)
    folder = build(args.out, spec, device=args.device, chunks=None if ray is None else chunk_builder(ray))
    print(f"data set of {spec.scenes} scenes ({spec.width}x{spec.height}) in {time.perf_counter() - start:.0f} s "
          f"-> {folder}")
    return 0


def add_parser(sub) -> argparse.ArgumentParser:
    from tpnet_gpu.config import DatasetSpec  # noqa: PLC0415 - light: numpy only

    spec = DatasetSpec()
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
    data.add_argument("--curved", type=float, default=spec.curved, metavar="P",
                      help="probability that each random object is a sphere or an upright cylinder instead of a "
                           f"plane (curved and steep surfaces, as in photographs; default {spec.curved})")
    data.add_argument("--device", default=None, help=DEVICE_HELP)
    data.set_defaults(func=run)
    return data
