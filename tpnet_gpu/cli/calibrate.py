"""``tpnet calibrate SCENE... --rig IN --out OUT``: fit the quad's extrinsic corrections to scene folders
(``tpnet_gpu.calibration.calibrate``, docs/calibration.md) and write the calibrated rig file."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _rig_suffix(out) -> None:
    if Path(out).suffix.lower() not in (".json", ".toml"):
        raise ValueError(f"--out: expected a .json or .toml rig file, got {out}")


def write_rig_atomically(rig, out: Path, *, overwrite: bool, description: str) -> Path:
    """Write ``rig`` (``rigfile.write_rig``) whole or not at all, under the claim on ``out``
    (``outputs.output_file``: a temporary file beside it, renamed into place). An existing ``out`` is refused
    without ``overwrite``."""
    from tpnet_gpu.io.rigfile import write_rig  # noqa: PLC0415 - numpy and the rig on use
    from tpnet_gpu.outputs import output_file  # noqa: PLC0415

    _rig_suffix(out)
    with output_file(out, overwrite=overwrite) as tmp:
        write_rig(rig, tmp, description=description)
    return Path(out)


def run(args: argparse.Namespace) -> int:
    from tpnet_gpu.outputs import claimed_file  # noqa: PLC0415

    _rig_suffix(args.out)  # before the work, not after it
    with claimed_file(args.out, overwrite=args.overwrite) as out:  # before the work, not after it
        return _claimed(args, out)


def _claimed(args: argparse.Namespace, out: Path) -> int:
    from tpnet_gpu.io import rigfile
    from tpnet_gpu.calibration import CalibrationConfig, Frame, calibrate, edge_misalignment
    from tpnet_gpu.scenes.folder import load

    # the library's default and its check (rounds >= 1), before the work
    config = CalibrationConfig() if args.rounds is None else CalibrationConfig(rounds=args.rounds)
    rig = rigfile.load(args.rig)
    frames = []
    for folder in args.scenes:
        if not Path(folder).is_dir():
            raise FileNotFoundError(f"SCENE: expected a scene folder, got {folder!r}, which is not a folder")
        scene = load(folder)
        if (scene.rig.width, scene.rig.height) != (rig.width, rig.height):
            raise ValueError(f"{folder}: expected {rig.width}x{rig.height} frames (--rig), got "
                             f"{scene.rig.width}x{scene.rig.height}")
        frames.append(Frame(scene.frames, scene.cfa))
    result = calibrate(frames, rig, method=args.method, config=config,
                       device=args.device, log=lambda m: print(m, file=sys.stderr))
    moved = edge_misalignment(rig, result.extrinsics, rig.extrinsics)
    write_rig_atomically(result.rig, out, overwrite=args.overwrite,
                         description=f"calibrated by tpnet calibrate ({args.method}) from {len(frames)} scene(s)")
    last = result.rounds[-1]
    print(f"calibrated {len(frames)} scene(s) by {args.method} in {len(result.rounds)} rounds, "
          f"{result.seconds:.1f} s: frame edge moved {moved:.3f} px from --rig, {last.get('tiles')} tiles -> {out}")
    return 0


def add_parser(sub) -> argparse.ArgumentParser:
    cal = sub.add_parser("calibrate", help="fit the quad's extrinsic corrections to scene folders: a calibrated "
                         "rig file", description="Field calibration (docs/calibration.md): the pairs' 2-D peaks of "
                         "many tiles give the rig's 13 extrinsic corrections (tilt, azimuth, roll, zoom), fitted by "
                         "a robust LMA (or gradient descent through the differentiable tile processor) with "
                         "re-correlation; the common roll and the toe-in are unobservable and left as in --rig.")
    cal.add_argument("scenes", nargs="+", metavar="SCENE", help="scene folders of one rig (cam*.dng + scene.json)")
    cal.add_argument("--rig", required=True, metavar="IN",
                     help="the rig to start from: a rig file (.json/.toml, docs/rig_file.md) or a shipped one (quad)")
    cal.add_argument("--out", required=True, metavar="OUT", help="the calibrated rig file to write (.json/.toml)")
    cal.add_argument("--method", choices=("lma", "gradient"), default="lma", help="the fit (default lma)")
    cal.add_argument("--rounds", type=int, default=None, help="most measure + fit rounds (default: the library's, "
                     "CalibrationConfig.rounds)")
    cal.add_argument("--device", default=None, help="cpu or cuda (default: cuda when present)")
    cal.add_argument("--overwrite", action="store_true", help="replace an existing --out file (default: refuse)")
    cal.set_defaults(func=run)
    return cal
