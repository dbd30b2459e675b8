"""``tpnet demo``: the built-in rendered scene through the whole frame pipeline, with figures and a report.

Writes into the output folder the frame's files (``tpnet_gpu.outputs.frame_outputs``: disparity, confidence, depth,
points.ply, texture) and, against the rendered ground truth (``tpnet_gpu.demo.report``): ``ground_truth.tif``,
``error.tif`` (final - ground truth, px), their figures, ``comparison.png`` (the ground truth beside the
disparities and their errors), ``correlations.png`` (the pair correlations of a few tiles; ``correlations_figure.png`` labelled) and the report
(``report.md`` with the figures, ``report.txt``, ``report.json``: RMSE per tile class, timing). docs/outputs.md.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from tpnet_gpu import evaluation, outputs
from tpnet_gpu.outputs import frame_outputs
from tpnet_gpu.io.images import save_png
from tpnet_gpu.runtime.progress import Steps

log = logging.getLogger(__name__)


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
             backend: str | None = None, weights=None, figures: bool = True, overwrite: bool = False,
             progress: bool = True) -> dict:
    """Render the demo scene, run the pipeline (with ``weights``: TPNET weights from ``tpnet train``; default the
    shipped ones), write the files and the report into ``out`` (whole or not at all; a folder holding anything
    but an earlier demo's output only with ``overwrite``: ``outputs``, ``demo_report.is_demo_output``); ``figures`` False: no matplotlib figures. Returns the report."""
    from tpnet_gpu.demo import report as demo_report  # noqa: PLC0415 - heavy imports on use

    # a demo's own earlier output is refreshed; a folder of other files needs ``overwrite``
    own = demo_report.is_demo_output(out)
    overwrite = overwrite or own
    with outputs.claimed(out, overwrite=overwrite) as out:  # before the work, not after it
        return _claimed(out, width, height, seed, device, backend, weights, figures, overwrite, own, progress)


def _claimed(out, width, height, seed, device, backend, weights, figures, overwrite, own, progress) -> dict:
    from tpnet_gpu.demo import report as demo_report  # noqa: PLC0415 - heavy imports on use
    from tpnet_gpu.camera import Rig
    from tpnet_gpu.pipeline import Pipeline
    from tpnet_gpu.scenes import Sensor, demo_scene, render

    rig = Rig(width=width, height=height)
    with Steps(rig.cams + 4, desc="demo", logger=log, progress=progress) as step:
        step("pipeline set-up")  # first: weights that do not fit are refused before the render
        start = time.perf_counter()
        pipeline = Pipeline(height, width, weights=weights, device=device, backend=backend)
        t_setup = time.perf_counter() - start
        start = time.perf_counter()
        rendered = render(demo_scene(rig, seed=seed), rig, sensor=Sensor(), seed=seed,
                          progress=lambda m: step(f"rendering {m}"))
        t_render = time.perf_counter() - start
        frames = rendered.raws.astype(np.float32) - rendered.sensor.black_level
        step("first frame (kernels compile or load)")
        pipeline.process(frames)
        step("timed frame")
        start = time.perf_counter()
        result = pipeline.process(frames)
        t_frame = time.perf_counter() - start
        step("outputs" + (" and figures" if figures else ""))
        what = frame_outputs.method(pipeline)
        maps = frame_outputs.from_result(result, rig, white=rendered.sensor.white_level - rendered.sensor.black_level)
        gt = rendered.tile_disparity
        initial = result.initial.cpu().numpy().astype(np.float64)
        classes = evaluation.tile_classes(gt, rendered.tile_confidence, rendered.tile_spread)
        stats = {name: {c: evaluation.error_stats(est, gt, mask) for c, mask in classes.items()}
                 for name, est in (("tpnet", maps.disparity.astype(np.float64)),
                                   ("disparity engine (network input)", initial))}
        scene = f"demo-{seed}"
        with outputs.output_folder(out, overwrite=overwrite, keep_others=not own) as folder:
            written = frame_outputs.write(folder, maps, scene=scene, what=what, figures=figures)
            written += demo_report.write_truth(folder, maps, gt, initial, scene=scene, what=what, figures=figures)
            tiles = [int(np.ravel_multi_index((ty, tx), gt.shape)) for ty, tx in
                     ((gt.shape[0] // 2, gt.shape[1] // 4), (gt.shape[0] * 3 // 4, gt.shape[1] // 2),
                      (gt.shape[0] // 3, gt.shape[1] * 3 // 4))]
            tp = pipeline.network_tp or pipeline.engine.tp
            corr = tp.result.corr.cpu().numpy()
            save_png(folder / "correlations.png", correlation_sheet(corr, tiles))
            written.append("correlations.png")
            if figures:
                from tpnet_gpu.outputs.figures import save_correlations  # noqa: PLC0415 - matplotlib on use

                save_correlations(folder / "correlations_figure.png", corr[tiles],
                                  [np.unravel_index(t, gt.shape) for t in tiles], tp.pairs,
                                  title=f"scene {scene}: pair correlations at the final disparity ({what})")
                written.append("correlations_figure.png")
            report = {
                "scene": scene, "size": [width, height], "device": str(pipeline.device), "method": what,
                "weights": None if pipeline.weights is None else str(pipeline.weights),
                "seconds": {"render": t_render, "pipeline_setup": t_setup, "frame": t_frame},
                "tile_passes": result.tile_passes, "stats": stats, "files": sorted(written),
            }
            report["text"] = demo_report.write_report(folder, report, out=out, figures=figures)
    return report
