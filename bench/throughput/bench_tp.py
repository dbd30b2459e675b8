"""Tile-processor speed benchmark: the Warp stages of ``TileProcessor`` against the vectorised NumPy peer.

    tpnet bench tp [--device cpu|cuda] [--height 1936 --width 2592] [--repeat 3] [--json out/bench_tp.json]
    python -m tpnet_gpu.bench.throughput.bench_tp [same options]

One quad frame (4 cameras, random 12-bit raw values, seeded), every tile at one target disparity. The processor is
built once; ``prepare`` (input mapping, padding, tile centres) runs once and is not part of the stage timings.
Each stage is timed on its own, the Warp stages with a device synchronisation before the timer stops. The first
pass of each implementation is a warm-up (Warp: kernel compilation; NumPy: first touch of its buffers), then
``--repeat`` passes give median and best. The NumPy peer (bench/twins/numpy_tp.py) gets the processor's own tile
centres and correlation parameters, and the two results are compared (max |numpy - warp| / max |warp|).

Prints a table (stage | warp ms | numpy ms | ratio numpy/warp) and writes the numbers with machine information to
JSON. Progress goes to stderr. To add a stage, add one ``Stage`` entry to ``STAGES``.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch
import warp as wp

from tpnet_gpu import tables
from tpnet_gpu.processor import TileProcessor

from tpnet_gpu.bench import common
from tpnet_gpu.bench.common import PAPER_GPU, PAPER_TP_MS, summary, timed_ms
from tpnet_gpu.bench.twins.numpy_tp import numpy_convert, numpy_correlate

log = common.logger("bench_tp")


@dataclass(frozen=True)
class Stage:
    """One timed stage: ``warp(tp)`` launches it on the processor; ``numpy(state)`` runs the NumPy peer, reading
    its inputs from and storing its output in the shared ``state`` dict (None: no NumPy peer yet)."""

    name: str
    warp: Callable[[TileProcessor], None]
    numpy: Callable[[dict], None] | None


def _numpy_convert(state: dict) -> None:
    state["clt"] = None  # drop the previous output first: at full frame it is ~1 GB
    state["clt"] = numpy_convert(state["frames"], state["centres"], state["cfa"])


def _numpy_correlate(state: dict) -> None:
    cfg = state["config"]
    state["corr"] = None
    state["corr"] = numpy_correlate(
        state["clt"], state["pairs"], cfg.colour_weights, cfg.fat_zero, cfg.sigma_rb, cfg.sigma_corr
    )


STAGES = (
    Stage("convert", lambda tp: tp.convert(), _numpy_convert),
    Stage("correlate", lambda tp: tp.correlate(), _numpy_correlate),
    Stage("texture", lambda tp: tp.texture(), None),  # no NumPy twin: the float64 reference is the oracle
)


def run_passes(label: str, stages, run_stage: Callable[[Stage], float], repeat: int) -> tuple[dict, dict]:
    """One warm-up pass and ``repeat`` timed passes over ``stages``; returns (warm-up ms, run ms lists) by name."""
    warmup = {}
    for stage in stages:
        log(f"{label} warm-up: {stage.name} ...")
        warmup[stage.name] = run_stage(stage)
        log(f"{label} warm-up: {stage.name} {warmup[stage.name]:.1f} ms")
    runs = {stage.name: [] for stage in stages}
    for r in range(repeat):
        for stage in stages:
            runs[stage.name].append(run_stage(stage))
        log(f"{label} run {r + 1}/{repeat}: " + ", ".join(f"{s.name} {runs[s.name][-1]:.1f} ms" for s in stages))
    return warmup, runs


def max_relative_difference(got: np.ndarray, want: np.ndarray) -> float:
    """max |got - want| / max |want|, one camera or pair (axis 1) at a time (no full-size temporaries)."""
    diff = max(float(np.abs(got[:, i] - want[:, i]).max()) for i in range(want.shape[1]))
    scale = max(float(want.max()), -float(want.min()))
    return diff / scale if scale > 0 else diff


def main(argv=None) -> dict:
    parser = common.parser(__name__, __doc__)
    common.frame_arguments(parser)
    parser.add_argument("--json", default="out/bench_tp.json", help="output JSON path ('' to skip)")
    args = parser.parse_args(argv)
    cfa = common.frame_cfa(parser, args)

    cams = len(tables.QUAD_OFFSETS)
    frames = common.random_frames(np.random.default_rng(args.seed), args.height, args.width, cams)

    # --- Warp -----------------------------------------------------------------------------------------------------
    start = time.perf_counter()
    tp = TileProcessor(args.height, args.width, cfa=cfa, textures=True, clt=True, device=args.device, backend="warp")
    setup_ms = 1e3 * (time.perf_counter() - start)
    log(f"{args.width}x{args.height}, {cams} cameras, {tp.tiles} tiles, {len(tp.pairs)} pairs on {tp.device} "
        f"({common.device_name(tp.device)}); processor built in {setup_ms:.0f} ms")
    frames_t = torch.from_numpy(frames).to(tp.torch_device)  # float32, contiguous: read in place

    def sync() -> None:
        wp.synchronize_device(tp.device)

    prepare_first_ms = timed_ms(lambda: tp.prepare(frames_t, args.disparity), sync)  # compiles its kernels
    warp_warmup, warp_runs = run_passes("warp", STAGES, lambda s: timed_ms(lambda: s.warp(tp), sync), args.repeat)
    log("warp: one process() call (prepare + all stages) for the centres and the comparison ...")
    result = None

    def process() -> None:
        nonlocal result
        result = tp.process(frames_t, args.disparity)

    process_ms = timed_ms(process, sync)

    # --- NumPy ----------------------------------------------------------------------------------------------------
    numpy_stages = [s for s in STAGES if s.numpy is not None]
    state = {
        "frames": frames,
        "centres": result.centres.cpu().numpy(),  # the processor's own per-camera tile centres
        "cfa": cfa,
        "pairs": tables.QUAD_PAIRS,
        "config": tp.config,
    }
    numpy_warmup, numpy_runs = run_passes("numpy", numpy_stages, lambda s: timed_ms(lambda: s.numpy(state)),
                                          args.repeat)

    log("comparing results ...")
    agreement = {
        "clt_max_rel_diff": max_relative_difference(state["clt"], result.clt.cpu().numpy()),
        "corr_max_rel_diff": max_relative_difference(state["corr"], result.corr.cpu().numpy()),
    }

    # --- report ---------------------------------------------------------------------------------------------------
    stages = []
    for s in STAGES:
        warp_ms = summary(warp_runs[s.name])
        numpy_ms = summary(numpy_runs[s.name]) if s.name in numpy_runs else None
        ratio = numpy_ms["median"] / warp_ms["median"] if numpy_ms else None
        stages.append({"name": s.name, "warp_ms": warp_ms, "numpy_ms": numpy_ms, "ratio_numpy_over_warp": ratio,
                       "warmup_ms": {"warp": warp_warmup[s.name], "numpy": numpy_warmup.get(s.name)}})
    both = [s.name for s in numpy_stages]
    warp_total = summary([sum(r) for r in zip(*(warp_runs[n] for n in warp_runs))])
    numpy_total = summary([sum(r) for r in zip(*(numpy_runs[n] for n in both))])
    warp_total_same = summary([sum(r) for r in zip(*(warp_runs[n] for n in both))])
    total = {"warp_ms": warp_total, "numpy_ms": numpy_total,
             "ratio_numpy_over_warp": numpy_total["median"] / warp_total_same["median"], "ratio_over_stages": both}

    report = {
        "frame": common.frame_info(args, cfa, cams, tp.tiles, len(tp.pairs)),
        "timing": {"repeat": args.repeat, "statistic": "median (best and all runs listed)",
                   "warp_sync": "wp.synchronize_device before each timer stops",
                   "excluded": "prepare (input mapping, padding, tile centres) and the warm-up pass",
                   "warp_process_ms": "one whole process() call (prepare + all stages), after the timed runs"},
        "stages": stages,
        "total": total,
        "warp_setup_ms": setup_ms,
        "warp_first_prepare_ms": prepare_first_ms,
        "warp_process_ms": process_ms,
        "agreement": agreement,
        "device": {"warp_device": str(tp.device), "name": common.device_name(tp.device), "is_cuda": tp.device.is_cuda},
        "machine": common.machine_info(
            threads="Warp CPU kernels run on one thread; NumPy's BLAS calls use all cores unless limited"),
        "paper": {"tp_ms": PAPER_TP_MS, "gpu": PAPER_GPU,
                  "note": "whole tile processor, one full quad frame; comparable only with CUDA timings"},
    }
    print_table(report)
    if args.json:
        log(f"wrote {common.save_json(report, args.json)}")
    return report


def print_table(report: dict) -> None:
    f, t = report["frame"], report["timing"]

    def ms(x):
        return "-" if x is None else f"{x['median']:.1f}"

    def ratio(x):
        return "-" if x is None else f"{x:.2f}"

    print(f"Tile processor, {f['width']}x{f['height']}, {f['cameras']} cameras ({f['cfa'] or 'mono'}), "
          f"{f['tiles']} tiles, {f['pairs']} pairs")
    print(f"device: {report['device']['warp_device']} = {report['device']['name']}; "
          f"median of {t['repeat']} runs after a warm-up")
    rows = [(s["name"], ms(s["warp_ms"]), ms(s["numpy_ms"]), ratio(s["ratio_numpy_over_warp"]))
            for s in report["stages"]]
    tot = report["total"]
    rows.append(("total", ms(tot["warp_ms"]), ms(tot["numpy_ms"]), ratio(tot["ratio_numpy_over_warp"])))
    print("\n".join(common.format_table(("stage", "warp ms", "numpy ms", "ratio (numpy/warp)"), rows)))
    a = report["agreement"]
    print(f"numpy vs warp, max relative difference: clt {a['clt_max_rel_diff']:.2e}, "
          f"corr {a['corr_max_rel_diff']:.2e}")
    print(f"warp process() end to end (prepare + all stages, one call): {report['warp_process_ms']:.1f} ms")
    print(f"paper: {report['paper']['tp_ms']:.0f} ms for the whole TP on a {report['paper']['gpu']} "
          f"(only meaningful beside CUDA timings)")


if __name__ == "__main__":
    sys.exit(common.run(main))
