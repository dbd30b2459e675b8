"""The demo's files against the rendered ground truth and its report (``tpnet_gpu.demo``; docs/outputs.md §3):
``ground_truth.tif`` and ``error.tif`` with their figures, ``comparison.png`` (ground truth beside the
disparities and their errors), and ``report.json`` / ``report.txt`` / ``report.md`` (the tables and figures)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from tpnet_gpu.outputs import pointcloud
from tpnet_gpu.outputs.frame_outputs import FrameMaps, texture_rgba

ERROR_SCALE_PX = 0.5  # the error figures' colour scale ends here (larger errors: the bar's "over" colour)
DISPARITY_PERCENTILE = 99  # the disparity figures' common scale: 0 .. this percentile of the ground truth
CLASSES = ("flat", "edge")  # the tile classes the text report lists (evaluation.tile_classes)


def write_truth(folder: Path, maps: FrameMaps, gt: np.ndarray, initial: np.ndarray, *, scene: str, what: str,
                figures: bool) -> list[str]:
    """Write ``ground_truth.tif`` (the rendered disparity at the tile centres, px), ``error.tif`` (final minus
    ground truth, px; NaN where unmeasured) and, with ``figures``, ``ground_truth.png``, ``error.png`` and
    ``comparison.png``. ``gt``, ``initial`` (the engine's disparity): ``(tiles_y, tiles_x)``."""
    import tifffile  # noqa: PLC0415

    error = (maps.disparity.astype(np.float64) - gt).astype(np.float32)
    tifffile.imwrite(folder / "ground_truth.tif", gt.astype(np.float32))
    tifffile.imwrite(folder / "error.tif", error)
    written = ["ground_truth.tif", "error.tif"]
    if not figures:
        return written
    from tpnet_gpu.outputs import figures as fig  # noqa: PLC0415 - matplotlib on use

    high = float(np.nanpercentile(gt, DISPARITY_PERCENTILE))
    gt_panel = fig.Panel(gt, "ground truth disparity (rendered)", "disparity", "px", "turbo", 0.0, high)
    disparity = fig.Panel(maps.disparity, f"disparity: {what}", "disparity", "px", "turbo", 0.0, high)
    abs_error = fig.Panel(np.abs(error), f"|error|: {what}", "|disparity - ground truth|", "px", "inferno", 0.0,
                          ERROR_SCALE_PX)
    engine_error = fig.Panel(np.abs(initial - gt), "|error|: disparity engine (network input)",
                             "|disparity - ground truth|", "px", "inferno", 0.0, ERROR_SCALE_PX)
    depth = fig.Panel(pointcloud.depth(gt, maps.rig), "ground truth depth", "depth Z", "m", "turbo_r", log=True)
    size = maps.size
    fig.save(folder / "ground_truth.png", gt_panel, title=f"scene {scene}", size=size)
    fig.save(folder / "error.png", abs_error, title=f"scene {scene}", size=size)
    panels = [gt_panel, disparity, abs_error, depth, engine_error]
    if maps.texture is not None:
        panels.append(fig.Panel(texture_rgba(maps.texture, maps.white), "texture at the final disparity"))
    fig.save(folder / "comparison.png", panels, title=f"scene {scene}: ground truth vs {what}", size=size, columns=3)
    return written + ["ground_truth.png", "error.png", "comparison.png"]


def _lines(report: dict, out) -> list[str]:
    seconds = report["seconds"]
    width, height = report["size"]
    lines = [f"tpnet demo: {width}x{height} quad frame of the built-in scene on {report['device']} "
             f"({report['method']})",
             f"render {seconds['render']:.1f} s, pipeline set-up {seconds['pipeline_setup']:.1f} s, one frame "
             f"{seconds['frame']:.2f} s (disparity engine: {report['tile_passes']:.1f} tile passes; network + texture)"]
    for name, per_class in report["stats"].items():
        parts = [f"{c} rmse {v['rmse_inliers']:.3f} px (median {v['median_abs']:.3f}, gross {v['gross']:.1%}, "
                 f"{v['tiles']} tiles)" for c, v in per_class.items() if c in CLASSES]
        lines.append(f"  {name}: " + "; ".join(parts))
    lines.append(f"  wrote {', '.join(report['files'])} and report.json/.txt/.md to {out}")
    return lines


def _markdown(report: dict, lines: list[str], figures: bool) -> str:
    md = [f"# tpnet demo: scene {report['scene']}", "", *(f"    {line}" for line in lines[:2]), "",
          "| method | tile class | tiles | RMSE of inliers, px | median abs error, px | gross (> 1 px) |",
          "|---|---|---|---|---|---|"]
    for name, per_class in report["stats"].items():
        for c, v in per_class.items():
            md.append(f"| {name} | {c} | {v['tiles']} | {v['rmse_inliers']:.3f} | {v['median_abs']:.3f} | "
                      f"{v['gross']:.1%} |")
    if figures:
        md += ["", "## Ground truth beside the results", "", "![comparison](comparison.png)", "",
               "Colour bars carry the units (px, m); axes are pixels (bottom, left) and tiles of 8 px (top, right); "
               "grey tiles have no value. Files: docs/outputs.md.", ""]
        md += [f"![{name}]({name}.png)" for name in ("ground_truth", "disparity", "error", "depth", "confidence")]
    return "\n".join(md) + "\n"


REPORT_FILES = ("report.json", "report.txt", "report.md")  # write_report's


def is_demo_output(folder) -> bool:
    """Whether ``folder`` holds a demo's output and nothing else: its ``report.json`` names a demo scene and every
    entry is a file that report lists (or the report itself). ``tpnet demo`` may replace such a folder without
    ``--overwrite``; any other file in it (or a report that does not parse) makes it someone else's."""
    folder = Path(folder)
    try:
        report = json.loads((folder / "report.json").read_text())
        listed = set(report["files"]) | set(REPORT_FILES)
        ours = isinstance(report["scene"], str) and report["scene"].startswith("demo-")
    except (OSError, ValueError, KeyError, TypeError, RecursionError):  # a crafted report: not ours
        return False
    return ours and all(entry.is_file() and entry.name in listed for entry in folder.iterdir())


def write_report(folder: Path, report: dict, *, out, figures: bool) -> str:
    """Write ``report.json``, ``report.txt`` and ``report.md`` (the table and, with ``figures``, the figures);
    returns the text report."""
    lines = _lines(report, out)
    (folder / "report.json").write_text(json.dumps(report, indent=1))
    (folder / "report.txt").write_text("\n".join(lines) + "\n")
    (folder / "report.md").write_text(_markdown(report, lines, figures))
    return "\n".join(lines)
