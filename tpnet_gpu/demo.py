"""``tpnet demo``: the built-in rendered scene through the whole frame pipeline, with pictures and a report.

Writes into the output folder: ``disparity.png`` (TPNET disparity per tile), ``error.png`` (|error| against the
rendered ground truth, 0 .. 0.5 px), ``texture.png`` (the RGBA texture), ``correlations.png`` (the 6 pair
correlations of a few tiles), ``report.json`` / ``report.txt`` (RMSE per tile class, timing).
"""

from __future__ import annotations

import json
import time

import numpy as np

from tpnet_gpu import evaluation, outputs
from tpnet_gpu.images import colour_ramp, save_png


def _upscale(tiles: np.ndarray, factor: int = 8) -> np.ndarray:
    return np.repeat(np.repeat(tiles, factor, axis=0), factor, axis=1)


def texture_rgba(texture: np.ndarray, white: float) -> np.ndarray:
    """``(4, H, W)`` R, G, B (raw units), alpha -> ``(H, W, 4)`` uint8 sRGB-ish (gamma 2.2) with alpha."""
    rgb = np.clip(texture[:3] / max(white, 1e-9), 0, 1) ** (1 / 2.2)
    alpha = np.clip(texture[3], 0, 1)
    return (np.concatenate([rgb, alpha[None]], axis=0).transpose(1, 2, 0) * 255 + 0.5).astype(np.uint8)


def correlation_sheet(corr: np.ndarray, tiles: list[int], zoom: int = 6) -> np.ndarray:
    """A grey sheet of the 6 pair correlations ``(15, 15)`` of each listed tile (rows: tiles, columns: pairs)."""
    rows = []
    for t in tiles:
        cells = []
        for p in range(corr.shape[1]):
            c = corr[t, p]
            c = (c - c.min()) / max(np.ptp(c), 1e-9)
            cells.append(np.pad(np.kron(c, np.ones((zoom, zoom))), 2, constant_values=1.0))
        rows.append(np.concatenate(cells, axis=1))
    return (np.concatenate(rows, axis=0) * 255).astype(np.uint8)


def run_demo(out="out/demo", *, width: int = 640, height: int = 480, seed: int = 0, device: str | None = None,
             backend: str | None = None, overwrite: bool = False) -> dict:
    """Render the demo scene, run the pipeline, write the pictures and the report into ``out`` (whole or not at
    all; a non-empty ``out`` only with ``overwrite``: ``tpnet_gpu.outputs``); returns the report."""
    from tpnet_gpu.camera import Rig  # noqa: PLC0415 - heavy imports on use
    from tpnet_gpu.pipeline import Pipeline
    from tpnet_gpu.scenes import Sensor, demo_scene, render

    out = outputs.check(out, overwrite=overwrite)  # before the work, not after it
    rig = Rig(width=width, height=height)
    start = time.perf_counter()
    rendered = render(demo_scene(rig, seed=seed), rig, sensor=Sensor(), seed=seed)
    t_render = time.perf_counter() - start
    frames = rendered.raws.astype(np.float32) - rendered.sensor.black_level
    start = time.perf_counter()
    pipeline = Pipeline(height, width, device=device, backend=backend)
    t_setup = time.perf_counter() - start
    pipeline.process(frames)  # first frame compiles / loads the kernels
    start = time.perf_counter()
    result = pipeline.process(frames)
    t_frame = time.perf_counter() - start

    gt = rendered.tile_disparity
    net = result.disparity.cpu().numpy().astype(np.float64)
    initial = result.initial.cpu().numpy().astype(np.float64)
    classes = evaluation.tile_classes(gt, rendered.tile_confidence, rendered.tile_spread)
    stats = {name: {c: evaluation.error_stats(est, gt, mask) for c, mask in classes.items()}
             for name, est in (("tpnet", net), ("disparity engine (network input)", initial))}
    high = float(np.nanpercentile(gt, 99))
    with outputs.output_folder(out, overwrite=overwrite) as folder:
        save_png(folder / "disparity.png", _upscale(colour_ramp(net, 0.0, high)))
        save_png(folder / "ground_truth.png", _upscale(colour_ramp(gt, 0.0, high)))
        save_png(folder / "error.png", _upscale(colour_ramp(np.abs(net - gt), 0.0, 0.5)))
        if result.texture is not None:
            white = rendered.sensor.white_level - rendered.sensor.black_level
            save_png(folder / "texture.png", texture_rgba(result.texture.cpu().numpy(), white))
        tiles = [int(np.ravel_multi_index((ty, tx), gt.shape)) for ty, tx in
                 ((gt.shape[0] // 2, gt.shape[1] // 4), (gt.shape[0] * 3 // 4, gt.shape[1] // 2),
                  (gt.shape[0] // 3, gt.shape[1] * 3 // 4))]
        corr = pipeline.network_tp.result.corr.cpu().numpy()
        save_png(folder / "correlations.png", correlation_sheet(corr, tiles))
        report = {
            "scene": f"demo-{seed}", "size": [width, height], "device": str(pipeline.device),
            "seconds": {"render": t_render, "pipeline_setup": t_setup, "frame": t_frame},
            "stats": stats,
            "files": sorted(p.name for p in folder.iterdir() if p.suffix == ".png"),
        }
        lines = [f"tpnet demo: {width}x{height} quad frame of the built-in scene on {pipeline.device}",
                 f"render {t_render:.1f} s, pipeline set-up {t_setup:.1f} s, one frame {t_frame:.2f} s "
                 f"(disparity engine: {result.tile_passes:.1f} tile passes; network + texture)"]
        for name, per_class in stats.items():
            parts = [f"{c} rmse {v['rmse_inliers']:.3f} px (median {v['median_abs']:.3f}, gross {v['gross']:.1%}, "
                     f"{v['tiles']} tiles)" for c, v in per_class.items() if c in ("flat", "edge")]
            lines.append(f"  {name}: " + "; ".join(parts))
        lines.append(f"  wrote {', '.join(report['files'])} and report.json to {out}")
        (folder / "report.json").write_text(json.dumps(report, indent=1))
        (folder / "report.txt").write_text("\n".join(lines) + "\n")
    report["text"] = "\n".join(lines)
    return report
