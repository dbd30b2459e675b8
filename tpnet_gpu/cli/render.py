"""``tpnet render``: a synthetic quad-camera scene folder - DNGs and ground truth (``tpnet_gpu.scenes``)."""

from __future__ import annotations

import argparse
import logging
import time

from tpnet_gpu.cli.common import OVERWRITE_HELP

RENDER_MIN_SIDE = 24  # the smallest multiple of 8 that rawio.LIBRAW_MIN_SIDE allows in a DNG


def run(args: argparse.Namespace) -> int:
    from tpnet_gpu.outputs import claimed  # noqa: PLC0415

    if not 0 <= args.seed < 2**63:  # numpy's generators take no other (its own message names nothing)
        raise ValueError(f"--seed: expected an integer in 0..2**63-1, got {args.seed}")
    for option, value in (("--width", args.width), ("--height", args.height)):
        if value % 8 or value < RENDER_MIN_SIDE:
            raise ValueError(f"{option}: expected a multiple of 8 that is at least {RENDER_MIN_SIDE} (LibRaw reads "
                             f"no smaller raw), got {value}")
    with claimed(args.out, overwrite=args.overwrite, option="out") as out:  # before the work, not after it
        return _claimed(args, out)


def _claimed(args: argparse.Namespace, out) -> int:
    import numpy as np  # noqa: PLC0415

    from tpnet_gpu.camera import Rig  # noqa: PLC0415
    from tpnet_gpu.outputs import output_folder  # noqa: PLC0415
    from tpnet_gpu.runtime.progress import Steps  # noqa: PLC0415
    from tpnet_gpu.scenes import Optics, Sensor, demo_scene, random_scene, render  # noqa: PLC0415
    from tpnet_gpu.scenes.folder import save  # noqa: PLC0415

    rig = Rig(width=args.width, height=args.height)
    scene = demo_scene(rig, seed=args.seed) if args.scene == "demo" else random_scene(rig, np.random.default_rng(args.seed))
    optics = Optics()
    sensor = Sensor() if args.bits is None else Sensor(bits=args.bits)  # None: the library's default, one door
    given = {} if args.supersample is None else {"supersample": args.supersample}
    start = time.perf_counter()
    with Steps(rig.cams, desc="render", logger=logging.getLogger("tpnet_gpu.cli")) as step:
        rendered = render(scene, rig, optics=optics, sensor=sensor, seed=args.seed, noise=not args.no_noise,
                          progress=lambda m: step(f"rendering {m}"), **given)
    seconds = time.perf_counter() - start
    with output_folder(out, overwrite=args.overwrite, option="out") as folder:
        save(rendered, folder, name=f"{args.scene}-{args.seed}", optics=optics)
    print(f"rendered {args.scene} scene (seed {args.seed}), {rig.cams} cameras of {rig.width}x{rig.height}, "
          f"{sensor.bits} bits, in {seconds:.1f} s -> {out}")
    return 0


def add_parser(sub) -> argparse.ArgumentParser:
    from tpnet_gpu.camera import Rig  # noqa: PLC0415 - light: numpy only

    rig = Rig()
    rend = sub.add_parser("render", help="render a synthetic quad-camera scene folder (DNGs + ground truth)")
    rend.add_argument("out", help="output folder")
    rend.add_argument("--scene", choices=("demo", "random"), default="demo", help="built-in scene kind")
    rend.add_argument("--seed", type=int, default=0, help="seed of the scene and the sensor noise")
    rend.add_argument("--width", type=int, default=rig.width, help="sensor width, pixels (multiple of 8)")
    rend.add_argument("--height", type=int, default=rig.height, help="sensor height, pixels (multiple of 8)")
    rend.add_argument("--supersample", type=int, default=None, help="sub-pixel rays per axis (default: the renderer's)")
    rend.add_argument("--bits", type=int, default=None, choices=(10, 12, 14, 16),
                      help="sensor bit depth (default: the sensor's)")
    rend.add_argument("--no-noise", action="store_true", help="no photon or read noise")
    rend.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    rend.set_defaults(func=run)
    return rend
