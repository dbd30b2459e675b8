"""``tpnet export``: the network (stage 1 + stage 2, whole-frame form, frame size in tiles dynamic) to an ONNX file
(``tpnet_gpu.net.export``; needs the ``onnx`` extra)."""

from __future__ import annotations

import argparse
import sys


def run(args: argparse.Namespace) -> int:
    from tpnet_gpu.net import infer  # noqa: PLC0415 - torch on use
    from tpnet_gpu.net.export import OPSET, export_onnx  # noqa: PLC0415

    model = infer.load(args.weights)
    try:
        path = export_onnx(model, args.out, overwrite=args.overwrite, opset=args.opset or OPSET)
    except ModuleNotFoundError as exc:  # the onnx extra is missing: one line, as for bad input
        print(f"tpnet export: error: {exc}", file=sys.stderr)
        return 2
    g = model.layers
    print(f"exported TPNET ({args.weights or infer.DEFAULT_WEIGHTS.name}, {g} layers) -> {path}: inputs layers "
          f"(tiles_y, tiles_x, {g}, 9, 9) and target (tiles_y, tiles_x) float32, output disparity "
          "(tiles_y, tiles_x); tiles_y, tiles_x >= 2 dynamic")
    return 0


def add_parser(sub) -> argparse.ArgumentParser:
    """Register ``tpnet export`` on the subparsers ``sub``."""
    exp = sub.add_parser("export", help="write the network (whole-frame form, any frame size) to ONNX",
                         description="Writes TPNET's whole-frame form to ONNX: inputs `layers` (tiles_y, tiles_x, G, "
                                     "9, 9) and `target` (tiles_y, tiles_x), output `disparity` = target + residual "
                                     "(tiles_y, tiles_x), float32, frame size in tiles dynamic. Needs "
                                     "`pip install 'tpnet-gpu[onnx]'`.")
    exp.add_argument("out", help="the .onnx file to write")
    exp.add_argument("--weights", default=None, metavar="FILE",
                     help="TPNET weights (.pt, e.g. from `tpnet train`; default: the shipped quad weights)")
    exp.add_argument("--opset", type=int, default=None, help="ONNX opset (default and minimum: 18)")
    exp.add_argument("--overwrite", action="store_true", help="replace an existing file (default: refuse it)")
    exp.set_defaults(func=run)
    return exp
