"""Rendered image pairs that fail the way real photographs do: the pipeline against OpenCV SGBM, case by case.

Usage: ``tpnet bench rendered_pairs [--pairs DIR] [--cases a,b] [--size WxH] [--seed N] [--gt-step S]`` - renders
the suite of ``bench/accuracy/rendered_pairs.py`` (one case per cause: exposure and tone differences, noise and JPEG, vertical
misalignment, blur, half-occlusions, periodic patterns, thin structures, faint texture, all camera causes
together; "clean" is the reference) in the ``realdata`` layout, then scores it exactly as ``tpnet bench real``
does (same methods, same table). ``--pairs DIR`` keeps the pairs (a new or empty folder) so that
``tpnet bench real DIR`` or ``tpnet process DIR/CASE/left.png DIR/CASE/right.png`` can read them again.
"""

from __future__ import annotations

import sys
import tempfile

from tpnet_gpu.bench import common
from tpnet_gpu.bench.accuracy import bench_real
from tpnet_gpu.bench.accuracy import rendered_pairs as suite


def main(argv=None) -> dict:
    parser = common.parser(__name__, __doc__, full_help=True)
    parser.add_argument("--pairs", default="", help="keep the rendered pairs in this new or empty folder")
    parser.add_argument("--cases", default=",".join(suite.CASES), help="comma-separated cases (default: all)")
    parser.add_argument("--size", default=f"{suite.SIZE[0]}x{suite.SIZE[1]}", help="WxH, multiples of 8")
    parser.add_argument("--seed", type=int, default=0, help="seed of the layout and the noise")
    parser.add_argument("--gt-step", type=float, default=None,
                        help="score against the GT rounded to this step, px (the real pairs' GT: 1/8 to 1 px)")
    bench_real.add_run_options(parser, "out/bench_rendered_pairs.json", "")
    args = parser.parse_args(argv)
    common.require_extras("cv2")
    cases = tuple(c for c in args.cases.split(",") if c)
    unknown = sorted(set(cases) - set(suite.CASES))
    if unknown or not cases:
        parser.error(f"--cases: expected some of {','.join(suite.CASES)}, got {args.cases!r}")
    if args.seed < 0:
        parser.error(f"--seed: expected an integer >= 0, got {args.seed}")
    try:
        sizes = common.parse_sizes(args.size, "--size")
    except ValueError as exc:
        parser.error(str(exc))
    if len(sizes) != 1:
        parser.error(f"--size: expected one WxH, got {args.size!r}")
    (size,) = sizes
    with tempfile.TemporaryDirectory(prefix="tpnet-rendered-pairs-") as scratch:
        try:
            folders = suite.write_suite(args.pairs or scratch, cases=cases, size=size, seed=args.seed,
                                        gt_step=args.gt_step)
        except (FileExistsError, ValueError) as exc:
            parser.error(f"--pairs/--size/--gt-step: {exc}")
        scores = bench_real.bench_folders(folders, args.backend, args.device, args.figures, weights=args.weights)
        report = {"bench": "rendered_pairs", "cases": list(cases), "size": list(size), "seed": args.seed,
                  "gt_step": args.gt_step, **scores}
    if args.json:
        common.save_json(report, args.json)
    return report


if __name__ == "__main__":
    sys.exit(common.run(main))
