"""Shared by the accuracy benches (bench_accuracy, bench_network, bench_two_surface, bench_flow): their scenes
(``bench_scene``) and scene options, per-class statistics
(strict and either-surface gross, own-inlier and reference-tile RMSE, new gross errors, coverage, confidence
ranking; tpnet_gpu/evaluation.py), per-frame costs, RMSE vs 3x3 spread, table, PNG plot."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from tpnet_gpu import evaluation

from tpnet_gpu.bench.common import save_json

CLASSES = ("flat", "edge", "low_texture", "all")


def bench_scene(rig, seed: int, index: int):
    """Scene ``index`` of the accuracy benches' series ``seed`` (10000+: the held-out scenes): the demo scene
    first, then random scenes drawn from ``[seed, index]`` - one convention, so every bench scores the same."""
    from tpnet_gpu.scenes import demo_scene, random_scene  # noqa: PLC0415

    return demo_scene(rig, seed=seed) if index == 0 else random_scene(rig, np.random.default_rng([seed, index]))


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


def _concat(scenes: list[dict], get) -> np.ndarray | None:
    """``get(scene)`` of every scene flattened over tiles and joined (None if any scene has none)."""
    parts = [get(s) for s in scenes]
    if any(p is None for p in parts):
        return None
    return np.concatenate([np.asarray(p).reshape(-1, *np.shape(p)[2:]) for p in parts])


def summarise(scenes: list[dict], methods: list[str], reference: str | None = None) -> tuple[dict, dict]:
    """``scenes``: dicts with ``gt``, ``confidence``, ``spread`` ``(ty, tx)`` and ``estimates`` {method: (ty, tx)};
    optional ``surfaces`` ``(ty, tx, K, 3)`` (``Rendered.tile_surfaces``) and ``confidences`` {method: (ty, tx)}
    (the method's own confidence, higher = surer). Returns (stats {method: {class: error_stats}}, curves
    {method: [per spread bin error_stats]}). With a ``reference`` method, stats also hold ``rmse_common`` and
    ``new_gross`` / ``new_gross_share`` on the tiles it gets within 1 px (the paper's protocol); with surfaces in
    every scene, ``gross_either``; every class also holds ``confidence_ranking`` (evaluation.confidence_ranking,
    None for a method without confidences in every scene). See tpnet_gpu/evaluation.py for the definitions."""
    gt = np.concatenate([s["gt"].ravel() for s in scenes])
    common = None if reference is None else np.concatenate(
        [evaluation.reference_inliers(s["estimates"][reference], s["gt"]).ravel() for s in scenes])
    surfaces = _concat(scenes, lambda s: s.get("surfaces"))
    per_scene = [evaluation.tile_classes(s["gt"], s["confidence"], s["spread"]) for s in scenes]
    masks = {c: np.concatenate([m[c].ravel() for m in per_scene]) for c in CLASSES}
    s3 = np.concatenate([evaluation.neighbourhood_spread(s["gt"]).ravel() for s in scenes])
    stats, curves = {}, {}
    for method in methods:
        est = np.concatenate([s["estimates"][method].ravel() for s in scenes])
        conf = _concat(scenes, lambda s: s.get("confidences", {}).get(method))  # noqa: B023
        stats[method] = {c: {**evaluation.error_stats(est, gt, masks[c], common, surfaces),
                             "confidence_ranking": evaluation.confidence_ranking(est, conf, gt, masks[c],
                                                                                 surfaces=surfaces)}
                         for c in CLASSES}
        curves[method] = [
            {"spread_low": low, "spread_high": high,
             **evaluation.error_stats(est, gt, masks["all"] & (s3 >= low) & (s3 < high), common, surfaces)}
            for low, high in zip(evaluation.SPREAD_BINS[:-1], evaluation.SPREAD_BINS[1:])]
    return stats, curves


PER_FRAME = {"tile_passes": ("passes", "{:9.0f}"), "seconds": ("s/frame", "{:8.2f}")}  # key: (column, format)


def per_frame(scenes: list[dict], methods: list[str]) -> dict:
    """The costs the bench handed in per scene (``scene["per_frame"]`` = {method: {"tile_passes": tile
    measurements that frame took, "seconds": its wall time}}, any subset), averaged over the scenes that report
    each: {method: {key: mean}} (methods or keys no scene reports are left out)."""
    out = {}
    for method in methods:
        values = {}
        for scene in scenes:
            for key, value in (scene.get("per_frame") or {}).get(method, {}).items():
                if value is not None:
                    values.setdefault(key, []).append(float(value))
        if values:
            out[method] = {key: float(np.mean(v)) for key, v in values.items()}
    return out


def _rate(value, width: int, digits: int = 1) -> str:
    """A share as a percentage, right-aligned; blank for None, '-' for NaN (no tiles)."""
    if value is None:
        return " " * width
    return f"{'-' if np.isnan(value) else f'{value:.{digits}%}':>{width}}"


def _px(value, width: int) -> str:
    """Pixels with 3 decimals, right-aligned; blank for None, '-' for NaN (no tiles)."""
    if value is None:
        return " " * width
    return f"{'-' if np.isnan(value) else f'{value:.3f}':>{width}}"


def _ratio(value: float, reference: float) -> str:
    ratio = value / reference if reference else float("nan")
    return "-" if np.isnan(ratio) else f"{ratio:.2f}x"


def _ranking_cell(ranking: list[dict] | None, index: int) -> str:
    if ranking is None:
        return ""
    row = ranking[index]
    either = "/" + _rate(row["gross_either"], 6).strip() if "gross_either" in row else ""
    return _rate(row["gross"], 6).strip() + either


def table(stats: dict, title: str, reference: str, per_frame: dict | None = None) -> list[str]:
    """Text table (about 140 characters wide with the benches' method names): a legend, then one block of rows
    per tile class, a row per method: strict and either-surface gross shares, RMSE on the method's own inliers,
    ``rmse-ref`` and its ratio to ``reference``'s (``x ref``), the tiles it makes gross that ``reference`` had
    within 1 px, coverage, the gross shares among its most confident tiles (when it has confidences) and its
    tile-passes and seconds per frame (``per_frame``, as :func:`per_frame`). Blank where absent: no
    confidences, no costs handed in, no reference in the stats (rmse-ref, x ref, new-gross)."""
    per_frame = per_frame or {}
    methods = list(stats)
    first = stats[methods[0]]["all"]
    common = "rmse_common" in first
    ranking = next((stats[m]["all"]["confidence_ranking"] for m in methods
                    if stats[m]["all"].get("confidence_ranking")), None)
    fractions = [r["fraction"] for r in ranking] if ranking else []
    name = max(6, *(len(m) for m in methods))
    tops = [f"top {f:.0%}" for f in fractions]
    head = (f"{'method':{name}} | {'gross':>6} {'either':>6} {'rmse-in':>7} {'rmse-ref':>8} {'x ref':>7} "
            f"{'new-gross':>11} {'cover':>5} {'right':>5} | " + " ".join(f"{t:>13}" for t in tops) + (" | " if tops else "")
            + " ".join(f"{column:>{len(fmt.format(0))}}" for column, fmt in PER_FRAME.values()))
    legend = ("gross: |error| > 1 px (error: vs the centre ray's disparity); either: > 1 px from every surface "
              f"covering >= {evaluation.MIN_SURFACE_SHARE:.0%} of the tile's 16x16 window; rmse-in: RMSE on the "
              "method's own inliers (|error| <= 1 px); "
              + (f"rmse-ref: RMSE on the tiles {reference} gets within 1 px (the paper's protocol), x ref: its ratio "
                 f"to {reference}'s; new-gross: tiles {reference} gets within 1 px that the method makes gross "
                 "(count, share of them); " if common else "")
              + "cover: share of the tiles with an estimate; right: share of the tiles with one within 1 px; "
              + ("top N %: gross/either among the method's most confident N % of its estimates; " if tops else "")
              + "passes: tile-passes per frame, s/frame: seconds per frame (as the bench measured)")
    lines = [title, *textwrap.wrap(legend, len(head)), head, "-" * len(head)]
    for cls in CLASSES:
        lines.append(f"{cls} ({stats[methods[0]][cls]['tiles']} tiles)")
        for method in methods:
            v = stats[method][cls]
            new = "" if not common else "(ref)" if method == reference else (
                f"{v['new_gross']} {_rate(v['new_gross_share'], 5).strip()}")
            ratio = "" if not common else _ratio(v["rmse_common"], stats[reference][cls]["rmse_common"])
            costs = per_frame.get(method, {})
            cells = [f"{method:{name}} | {_rate(v['gross'], 6)} {_rate(v.get('gross_either'), 6)} "
                     f"{_px(v['rmse_inliers'], 7)} {_px(v.get('rmse_common'), 8)} {ratio:>7} {new:>11} "
                     f"{_rate(v['coverage'], 5, 0)} {_rate(v.get('right'), 5, 0)} |"]
            if tops:
                cells.append(" ".join(f"{_ranking_cell(v['confidence_ranking'], i):>13}" for i in range(len(tops)))
                             + " |")
            cells.append(" ".join(fmt.format(costs[key]) if key in costs else " " * len(fmt.format(0))
                                  for key, (_, fmt) in PER_FRAME.items()))
            lines.append(" ".join(cells).rstrip())
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
    """The accuracy benches' common end: statistics (:func:`summarise`, against ``reference``), the per-frame
    costs (:func:`per_frame`), the table printed, the JSON (``meta`` + stats, per_frame, curves and table) and
    the RMSE-vs-spread PNG written (each unless its path is empty). Returns the report."""
    stats, curves = summarise(scenes, methods, reference=reference)
    costs = per_frame(scenes, methods)
    lines = table(stats, title, reference=reference, per_frame=costs)
    print("\n".join(lines))
    report = {**meta, "stats": stats, "per_frame": costs, "rmse_by_spread": curves, "table": lines}
    saved = []
    if json_path:
        saved.append(str(save_json(report, json_path)))
    if png_path:
        plot(curves, png_path, title)
        saved.append(str(png_path))
    if saved:
        log(f"saved {' and '.join(saved)}")
    return report
