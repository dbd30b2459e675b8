"""Shared by the accuracy benches (bench_accuracy, bench_network): their scene options, per-class statistics, RMSE
vs 3x3 spread, table, PNG plot."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tpnet_gpu import evaluation

from .common import save_json

CLASSES = ("flat", "edge", "low_texture", "all")


def scene_arguments(parser, bench: str, *, scenes: int, width: int, height: int, seed: int) -> None:
    """The accuracy benches' common options (with this bench's defaults): rendered scenes, their size and first
    seed, the device, and the JSON and PNG outputs ``out/bench_<bench>.json|png`` ('' skips one)."""
    parser.add_argument("--scenes", type=int, default=scenes)
    parser.add_argument("--width", type=int, default=width)
    parser.add_argument("--height", type=int, default=height)
    parser.add_argument("--seed", type=int, default=seed)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--json", default=f"out/bench_{bench}.json", help="output JSON path ('' to skip)")
    parser.add_argument("--png", default=f"out/bench_{bench}.png", help="RMSE-vs-spread plot ('' to skip)")


def summarise(scenes: list[dict], methods: list[str], reference: str | None = None) -> tuple[dict, dict]:
    """``scenes``: dicts with ``gt``, ``confidence``, ``spread`` ``(ty, tx)`` and ``estimates`` {method: (ty, tx)}.
    Returns (stats {method: {class: error_stats}}, curves {method: [per spread bin error_stats]}); with a
    ``reference`` method, stats also hold ``rmse_common`` on the tiles it gets within 1 px (the paper's protocol)."""
    gt = np.concatenate([s["gt"].ravel() for s in scenes])
    common = None if reference is None else np.concatenate(
        [evaluation.reference_inliers(s["estimates"][reference], s["gt"]).ravel() for s in scenes])
    per_scene = [evaluation.tile_classes(s["gt"], s["confidence"], s["spread"]) for s in scenes]
    masks = {c: np.concatenate([m[c].ravel() for m in per_scene]) for c in CLASSES}
    s3 = np.concatenate([evaluation.neighbourhood_spread(s["gt"]).ravel() for s in scenes])
    stats, curves = {}, {}
    for method in methods:
        est = np.concatenate([s["estimates"][method].ravel() for s in scenes])
        stats[method] = {c: evaluation.error_stats(est, gt, masks[c], common) for c in CLASSES}
        curves[method] = [
            {"spread_low": low, "spread_high": high,
             **evaluation.error_stats(est, gt, masks["all"] & (s3 >= low) & (s3 < high), common)}
            for low, high in zip(evaluation.SPREAD_BINS[:-1], evaluation.SPREAD_BINS[1:])]
    return stats, curves


def table(stats: dict, title: str, reference: str) -> list[str]:
    """Text table: per method and class rmse, rmse without gross errors, median, gross share, coverage (and
    ``rmse-ref``, the RMSE on the tiles ``reference`` gets within 1 px, when the stats hold it); then the
    ratios of every other method to ``reference``."""
    methods = list(stats)
    common = "rmse_common" in stats[methods[0]]["all"]
    keys = ("rmse", "rmse_inliers") + (("rmse_common",) if common else ())
    width = 45 if common else 37
    header = "rmse rmse-in " + ("rmse-ref " if common else "") + "median gross cover"
    lines = [title + "; gross = |error| > 1 px, rmse-in = RMSE without them"
             + (f", rmse-ref = RMSE on the tiles {reference} gets within 1 px (the paper's protocol)" if common else ""),
             f"{'method':36} | " + " | ".join(f"{c:^{width}}" for c in CLASSES),
             f"{'':36} | " + " | ".join(f"{header:>{width}}" for _ in CLASSES),
             "-" * (39 + (width + 3) * len(CLASSES))]
    for method in methods:
        cells = [f"{v['rmse']:6.3f} {v['rmse_inliers']:7.3f} " + (f"{v['rmse_common']:8.3f} " if common else "")
                 + f"{v['median_abs']:6.3f} {v['gross']:5.1%} {v['coverage']:5.0%}"
                 for v in (stats[method][c] for c in CLASSES)]
        lines.append(f"{method:36} | " + " | ".join(f"{cell:>{width}}" for cell in cells))
    for cls in ("flat", "edge", "all"):
        for key in keys:
            lines.append(f"{cls} tiles, {key} ratio method / {reference}: " + ", ".join(
                f"{m}: {stats[m][cls][key] / stats[reference][cls][key]:.2f}x" for m in methods if m != reference))
    return lines


def plot(curves: dict, path, title: str = "") -> None:
    """RMSE vs the 3x3 ground-truth spread (the paper's Figure 8), one line per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for method, bins in curves.items():
        pts = [(b["spread_low"] if np.isfinite(b["spread_high"]) else 1.5 * b["spread_low"], b["rmse_inliers"])
               for b in bins if b["tiles"] >= 5 and np.isfinite(b["rmse_inliers"])]
        ax.plot([p[0] + 0.05 for p in pts], [p[1] for p in pts], marker="o", label=method)
    ax.set_xscale("symlog", linthresh=0.25)
    ax.set_yscale("log")
    ax.set_xlabel("ground-truth max - min disparity over the 3x3 tiles (bin start), px")
    ax.set_ylabel("disparity RMSE without gross errors, px")
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


def publish(scenes: list[dict], methods: list[str], title: str, reference: str, meta: dict, json_path, png_path,
            log=print) -> dict:
    """The accuracy benches' common end: statistics (with ``rmse_common`` against ``reference``), the table
    printed, the JSON (``meta`` + stats, curves and table) and the RMSE-vs-spread PNG written (each unless its
    path is empty). Returns the report."""
    stats, curves = summarise(scenes, methods, reference=reference)
    lines = table(stats, title, reference=reference)
    print("\n".join(lines))
    report = {**meta, "stats": stats, "rmse_by_spread": curves, "table": lines}
    saved = []
    if json_path:
        saved.append(str(save_json(report, json_path)))
    if png_path:
        plot(curves, png_path, title)
        saved.append(str(png_path))
    if saved:
        log(f"saved {' and '.join(saved)}")
    return report
