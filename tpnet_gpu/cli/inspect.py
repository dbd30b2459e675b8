"""``tpnet inspect``: read a scene folder back through rawpy and summarise it (``tpnet_gpu.scenes.folder``)."""

from __future__ import annotations

import argparse


def run(args: argparse.Namespace) -> int:
    import numpy as np  # noqa: PLC0415

    from tpnet_gpu.scenes.folder import load  # noqa: PLC0415

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


def add_parser(sub) -> argparse.ArgumentParser:
    insp = sub.add_parser("inspect", help="read a scene folder back (rawpy) and summarise it")
    insp.add_argument("folder", help="scene folder (cam*.dng + scene.json)")
    insp.set_defaults(func=run)
    return insp
