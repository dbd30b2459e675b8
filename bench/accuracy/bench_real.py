"""Real rectified pairs with ground truth: the pipeline against OpenCV StereoSGBM on the same pairs.

Usage: ``tpnet bench real DIR...`` - pair folders (``bench/accuracy/real_pairs.py``: the ``realdata`` layout of
``../shared/realdata``, or Middlebury 2014 / ETH3D ``im0.png im1.png disp0GT.pfm``), or folders of them. Methods:
"tpnet" (``tpnet process LEFT RIGHT --max-disparity N --method tpnet``: the pipeline, its checks on, TPNET
with the weights shipped for mono pairs - on request only, so the default output is the engine's row), "engine"
(``--method engine``: no network), "tpnet, no checks" (every tile answered:
``PipelineConfig(cross_check=False)``), and SGBM (3WAY, block 5, P1 8b^2, P2 32b^2,
uniqueness 5, disp12MaxDiff 1, ``bench/twins/peers.py``), all on the images' luma. Scored per tile (the tile grid in
the left image; GT = half-sine-weighted mean of the window's GT, "fronto" = GT spread <= 1 px; SGBM's map sampled
the same way) - coverage, share > 1 px off (strict, and either-surface: within 1 px of >= 10 % of the window's
GT), fronto median (and the fronto inliers' median signed error and their scatter about it: a scene's GT
offset from its images is every method's bias, the scatter is the method's precision), share > 1 px off among the most confident answers as many as SGBM gives (ranked over every
tile the method answers before its confidence floor: for tpnet's per-pixel check, ``pixel_check.tile_answers``
of its result's pixels, so a default output below SGBM's coverage is ranked fairly) - and per pixel
(bad 1.0 / bad 2.0 / avgerr on non-occluded pixels where a mask exists, no answer counted bad): the pipeline's
``disparity_px``, its tile map spread over each tile's 8x8 cell, SGBM. Pooled = all scenes' tiles (pixels)
together. A table, JSON, and a figure per scene (left image, GT, ours, SGBM, error maps, one colour scale).
"""

from __future__ import annotations

import dataclasses
import functools
import sys
import time
from pathlib import Path

import numpy as np

from tpnet_gpu.bench import common
from tpnet_gpu.bench.twins import peers
from tpnet_gpu.bench.accuracy import real_pairs as rp

log = common.logger("real")
TILE_METHODS = ("tpnet", "engine", "tpnet, no checks", "SGBM")
PIXEL_METHODS = ("tpnet per pixel", "tpnet tile cells", "SGBM")


def pair_folders(paths) -> list[Path]:
    """Pair folders from ``paths``: each a pair folder, or a folder whose sub-folders are (sorted)."""
    folders = []
    for path in map(Path, paths):
        if not path.is_dir():
            raise ValueError(f"DIR: expected a folder of a pair or of pairs, got {path}")
        if any((path / name).is_file() for name in ("meta.json", "disp0GT.pfm")):
            folders.append(path)
            continue
        inside = sorted(p for p in path.iterdir() if p.is_dir() and any(
            (p / name).is_file() for name in ("meta.json", "disp0GT.pfm")))
        if not inside:
            raise ValueError(f"DIR: {path} holds no pair folder (meta.json or disp0GT.pfm)")
        folders += inside
    return folders


def run_pair(pair: rp.Pair, backend: str | None, device: str, weights=None) -> dict:
    """Every method's maps on one pair (host arrays cut to the image: tiles ``(ty, tx)``, pixels ``(h, w)``);
    ``weights``: the TPNET rows' weights (default: those shipped for mono pairs)."""
    from tpnet_gpu.disparity.pixel_check import tile_answers  # noqa: PLC0415 - torch and the kernels on use
    from tpnet_gpu.pipeline import Pipeline, PipelineConfig  # noqa: PLC0415
    from tpnet_gpu.io.stereo_io import load_inputs  # noqa: PLC0415

    inputs = load_inputs([pair.left, pair.right])  # as `tpnet process LEFT RIGHT` reads them
    frames, rig = inputs.frames, inputs.rig
    (height, width) = frames.padded
    out = {"size": frames.size}
    for name, config in (("tpnet", PipelineConfig(method="tpnet")),
                         ("engine", PipelineConfig(method="engine", textures=False)),
                         ("tpnet, no checks", PipelineConfig(cross_check=False, per_pixel=False, textures=False,
                                                             method="tpnet"))):
        given = {"weights": weights} if weights is not None and config.method != "engine" else {}
        make = functools.partial(Pipeline, height, width, cfa=None, rig=rig, min_disparity=0.0,
                                 max_disparity=pair.max_disparity, device=device, backend=backend, **given)
        try:  # the network wherever weights fit these frames, those shipped on request included (mono pairs)
            pipeline = make(config=config)
        except ValueError as exc:  # none fit: the pipeline's default, the engine's answers
            if not str(exc).startswith("method:"):
                raise
            pipeline = make(config=dataclasses.replace(config, method="auto"))
        pipeline.process(frames.frames)  # warm-up: kernels loaded, buffers touched
        start = time.perf_counter()
        result = pipeline.process(frames.frames)
        seconds = time.perf_counter() - start
        host = lambda t: None if t is None else t.detach().cpu().numpy().astype(np.float64)  # noqa: E731
        out[name] = {"tiles": frames.crop_tiles(host(result.disparity)),
                     "confidence": frames.crop_tiles(host(result.confidence)), "seconds": seconds}
        if result.pixels_measured is not None:  # every tile's answer and confidence, before the floor drops any
            # (the engine's answers where too few pixels were measured: the pipeline's own without weights)
            ranked = tile_answers(result.pixels, result.pixels_measured, result.initial)
            out[name]["ranked"] = tuple(frames.crop_tiles(host(t)) for t in ranked)
        if result.pixels is not None:
            out[name]["pixels"] = frames.crop_image(host(result.pixels))
    left, right = (frames.crop_image(f) for f in frames.frames)
    start = time.perf_counter()
    sgbm = peers.sgbm(left, right, pair.max_disparity)
    out["SGBM"] = {"pixels": sgbm.astype(np.float64), "tiles": rp.sample_tiles(sgbm, frames.tiles), "confidence": None,
                   "seconds": time.perf_counter() - start}
    out["left"] = left
    return out


def cells(tiles: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``(h, w)``: each pixel the answer of the tile whose 8x8 cell holds it."""
    import torch  # noqa: PLC0415

    from tpnet_gpu.disparity.per_pixel import cell_field  # noqa: PLC0415

    return cell_field(torch.from_numpy(tiles), tuple(size), 0, 0).numpy()


def score_pair(pair: rp.Pair, maps: dict) -> tuple[dict, dict]:
    """``(scores, pooled arrays)`` of one pair: per tile and per pixel, per method (module docstring)."""
    tiles = maps["tpnet"]["tiles"].shape
    truth, spread = rp.tile_truth(pair.gt, tiles)
    sg_cov = rp.tile_scores(maps["SGBM"]["tiles"], truth, spread)["coverage"]
    scores, arrays = {"tiles": {}, "pixels": {}}, {"truth": truth, "spread": spread}
    for name in TILE_METHODS:
        m = maps[name]
        either = rp.either_correct(m["tiles"], pair.gt)
        conf = m["confidence"]
        scores["tiles"][name] = rp.tile_scores(m["tiles"], truth, spread, conf, sg_cov if conf is not None else None,
                                               either)
        if conf is None:  # no ranking: its own answers are its "most confident" at its coverage
            scores["tiles"][name]["gross_at_coverage"] = scores["tiles"][name]["gross"]
        own = (m["tiles"], conf if conf is not None else np.ones_like(m["tiles"]))
        ranked = m.get("ranked", own)  # every answer before the confidence floor, where the result has them
        arrays[name] = (*own, either, *ranked)
        if "ranked" in m:
            scores["tiles"][name]["gross_at_coverage"] = rp.gross_at_coverage(ranked[0], truth, ranked[1], sg_cov)
    pixel_maps = {"tpnet per pixel": maps["tpnet"]["pixels"], "tpnet tile cells": cells(maps["tpnet"]["tiles"],
                  maps["size"]), "SGBM": maps["SGBM"]["pixels"]}
    scored = np.isfinite(pair.gt) if pair.mask is None else np.isfinite(pair.gt) & pair.mask
    for name, values in pixel_maps.items():
        scores["pixels"][name] = rp.pixel_scores(values, pair.gt, pair.mask)
        arrays[f"px {name}"] = values[scored]
    arrays["px gt"] = pair.gt[scored]
    arrays["masked"] = pair.mask is not None
    scores["seconds"] = {name: maps[name]["seconds"] for name in TILE_METHODS}
    return scores, arrays


def pooled(arrays: list[dict]) -> dict:
    """Scores of all pairs' tiles together, and of their pixels (all pairs, and the masked pairs only)."""
    cat = lambda key, i=None: np.concatenate([(a[key] if i is None else a[key][i]).ravel() for a in arrays])  # noqa
    truth, spread = cat("truth"), cat("spread")
    scene = np.concatenate([np.full(a["truth"].size, i) for i, a in enumerate(arrays)])  # each scene's bias
    out = {"tiles": {}, "pixels": {}, "pixels_masked": {}}
    sg = rp.tile_scores(cat("SGBM", 0), truth, spread)["coverage"]
    for name in TILE_METHODS:
        has_conf = name != "SGBM"
        out["tiles"][name] = rp.tile_scores(cat(name, 0), truth, spread, cat(name, 1) if has_conf else None,
                                            sg if has_conf else None, cat(name, 2), scene)
        if not has_conf:
            out["tiles"][name]["gross_at_coverage"] = out["tiles"][name]["gross"]
        else:  # ranked over every answer the method has (module docstring)
            out["tiles"][name]["gross_at_coverage"] = rp.gross_at_coverage(cat(name, 3), truth, cat(name, 4), sg)
    for key, chosen in (("pixels", arrays), ("pixels_masked", [a for a in arrays if a["masked"]])):
        if not chosen:
            continue
        gt = np.concatenate([a["px gt"] for a in chosen])
        for name in PIXEL_METHODS:
            out[key][name] = rp.pixel_scores(np.concatenate([a[f"px {name}"] for a in chosen]), gt, None)
            out[key][name]["masked"] = key == "pixels_masked"  # the pixels were chosen by each pair's mask
    return out


def figure(path: Path, pair: rp.Pair, maps: dict) -> None:
    """Left image, GT, ours (per pixel, tiles), SGBM and the error maps, one colour scale."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    low, high = np.nanpercentile(pair.gt, 1), np.nanpercentile(pair.gt, 99)
    ours, sg = maps["tpnet"]["pixels"], maps["SGBM"]["pixels"]
    panels = [("left image", maps["left"], "gray", None), ("ground truth, px", pair.gt, "turbo", (low, high)),
              ("tpnet per pixel, px", ours, "turbo", (low, high)),
              ("tpnet tiles, px", cells(maps["tpnet"]["tiles"], maps["size"]), "turbo", (low, high)),
              ("SGBM, px", sg, "turbo", (low, high)),
              ("|tpnet per pixel - GT|, px", np.abs(ours - pair.gt), "magma", (0, 3)),
              ("|SGBM - GT|, px", np.abs(sg - pair.gt), "magma", (0, 3))]
    fig, axes = plt.subplots(2, 4, figsize=(16, 6.5))
    for ax, (title, image, cmap, scale) in zip(axes.ravel(), panels):
        shown = ax.imshow(np.ma.masked_invalid(image), cmap=cmap, **({} if scale is None else
                                                                    {"vmin": scale[0], "vmax": scale[1]}))
        ax.set_title(title, fontsize=9)
        ax.axis("off")
        if scale is not None:
            fig.colorbar(shown, ax=ax, fraction=0.04)
    axes.ravel()[-1].axis("off")
    fig.suptitle(f"{pair.name}: no value = white (black in the error maps' masked areas)", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)


def _pct(v) -> str:
    return "-" if v is None or not np.isfinite(v) else f"{100 * v:.1f} %"


def table(per_scene: dict, pool: dict) -> list[str]:
    """Text tables: per tile and per pixel, a row per scene and method, then the pooled rows."""
    head = ["scene", "method", "coverage", "> 1 px (strict)", "> 1 px (either)", "fronto median px",
            "fronto bias / scatter px", "> 1 px at SGBM's coverage"]
    rows = []
    for scene, scores in list(per_scene.items()) + [("pooled", pool)]:
        for name, s in scores["tiles"].items():
            rows.append([scene, name, _pct(s["coverage"]), _pct(s["gross"]), _pct(s["gross_either"]),
                         f"{s['fronto_median']:.3f}", f"{s['fronto_bias']:+.3f} / {s['fronto_scatter']:.3f}",
                         _pct(s["gross_at_coverage"])])
    lines = ["Per tile (8x8 tiles of the left image; GT = the window's half-sine mean)", ""]
    lines += common.format_table(head, rows)
    head = ["scene", "method", "mask", "coverage", "bad 1.0", "bad 2.0", "avgerr px"]
    rows = []
    items = list(per_scene.items()) + [("pooled", {"pixels": pool["pixels"]}),
                                       ("pooled, masked pairs", {"pixels": pool["pixels_masked"]})]
    for scene, scores in items:
        for name, s in scores["pixels"].items():
            rows.append([scene, name, "nonocc" if s["masked"] else "all", _pct(s["coverage"]), _pct(s["bad1"]),
                         _pct(s["bad2"]), f"{s['avgerr']:.3f}"])
    lines += ["", "Per pixel (Middlebury's measures; no answer counts bad)", ""] + common.format_table(head, rows)
    return lines


def add_run_options(parser, json: str, figures: str) -> None:
    """The options of a bench that scores pair folders with ``bench_folders`` (defaults ``json``, ``figures``)."""
    parser.add_argument("--backend", default=None, help="tile-processor kernels (default: the library's)")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--json", default=json, help="output JSON path ('' to skip)")
    parser.add_argument("--figures", default=figures, help="folder of the per-scene figures ('' to skip)")
    parser.add_argument("--weights", default=None, help="the tpnet rows' TPNET weights (default: those shipped for "
                        "mono pairs): what a trained network adds on these pairs")


def main(argv=None) -> dict:
    parser = common.parser(__name__, __doc__, full_help=True)
    parser.add_argument("dirs", nargs="+", metavar="DIR", help="pair folders, or folders of them")
    add_run_options(parser, "out/bench_real.json", "out/bench_real")
    args = parser.parse_args(argv)
    common.require_extras("cv2")
    try:
        folders = pair_folders(args.dirs)
    except ValueError as exc:
        parser.error(str(exc))
    report = {"bench": "real", **bench_folders(folders, args.backend, args.device, args.figures,
                                                      weights=args.weights)}
    if args.json:
        common.save_json(report, args.json)
    return report


def bench_folders(folders, backend: str | None, device: str, figures, weights=None) -> dict:
    """Every method on each pair folder, scored; prints the table. ``figures``: folder of the per-scene figures
    (falsy: none); ``weights``: the tpnet rows' (``run_pair``). Returns the report's body (pairs, per scene,
    pooled, machine, table lines, weights)."""
    per_scene, arrays = {}, []
    for folder in folders:
        pair = rp.load_pair(folder)
        maps = run_pair(pair, backend, device, weights)
        scores, arr = score_pair(pair, maps)
        per_scene[pair.name] = scores
        arrays.append(arr)
        log(f"{pair.name}: tpnet {scores['seconds']['tpnet']:.2f} s, SGBM {scores['seconds']['SGBM']:.3f} s")
        if figures:
            figure(Path(figures) / f"{pair.name}.png", pair, maps)
    pool = pooled(arrays)
    lines = table(per_scene, pool)
    print("\n".join(lines))
    return {"pairs": [str(f) for f in folders], "per_scene": per_scene, "pooled": pool, "weights": weights,
            "machine": common.machine_info(), "table": lines}


if __name__ == "__main__":
    sys.exit(common.run(main))
