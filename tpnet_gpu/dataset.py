"""Training and test data for the network: rendered random scenes run through the tile processor.

Per scene (one compressed NPZ chunk) and per target variant, every tile's 4 network layers ``(4, 9, 9)``
(float16), its target disparity, and the ground truth (disparity at the tile centre, confidence, spread).
Variants (network.md §6): ``heuristic`` - targets from the disparity engine (``tpnet_gpu.disparity``, as the
pipeline runs it; tiles it cannot measure, ``measured`` False, get ground truth + a random offset); ``random`` - ground truth + a uniform offset in
+-``random_offset`` px; ``near0``, ``near1``, ... (``near_draws`` of them) - ground truth + an offset of
random sign and log-uniform size in ``near_offset`` px: the targets a second network pass starts from, which
teach the precision near the answer. Each chunk also keeps the scene's raw frames ``raws (cams, H, W)`` uint16
(``black_level`` included) and the window surfaces ``gt_surfaces (ty, tx, K, 3)``, so training and evaluation
can re-measure at new targets (a network's own earlier pass) and score either-surface. Scenes are split into train and test by scene. ``manifest.json`` lists
the chunks. Frames are scaled as the engine scales them (``DisparityEngine.normalise``) before the layers are
made, so training sees what the pipeline feeds the network.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from tpnet_gpu.camera import Rig
from tpnet_gpu.config import DatasetSpec  # noqa: F401 - DatasetSpec re-exported
from tpnet_gpu.scenes import Sensor, random_scene, render

FORMAT = "tpnet-dataset"
VERSION = 4  # 4: + the raw frames, the engine's measured mask and the window surfaces (re-measuring at new targets)


def _layers(processor, frames, target) -> np.ndarray:
    """Network layers ``(tiles_y, tiles_x, 4, 9, 9)`` float16 at ``target (tiles_y, tiles_x)``."""
    layers = processor.process(frames, target.astype(np.float32)).layers.detach().cpu().numpy()
    return layers.reshape(target.shape + layers.shape[1:]).astype(np.float16)


def build_scene(index: int, spec: DatasetSpec, engine, processor) -> dict:
    """Render scene ``index`` and return its arrays (see the module docstring). ``engine`` (a
    ``DisparityEngine`` of the spec's size) makes the heuristic targets; ``processor`` (correlating as
    ``spec.correlation()``; may be the engine's own) makes the network layers."""
    rig = Rig(width=spec.width, height=spec.height)
    rng = np.random.default_rng([spec.seed, index])
    rendered = render(random_scene(rig, rng), rig, sensor=Sensor(), supersample=spec.supersample,
                      seed=int(rng.integers(2**31)))
    frames = rendered.raws.astype(np.float32) - rendered.sensor.black_level
    gt = rendered.tile_disparity.astype(np.float64)
    shape = gt.shape
    heuristic = engine.run(frames).disparity.cpu().numpy().astype(np.float64)
    frames = engine.normalise(frames)
    measured = np.isfinite(heuristic)
    fallback = gt + rng.uniform(-spec.random_offset, spec.random_offset, shape)
    heuristic = np.where(measured, heuristic, fallback)
    targets = {"heuristic": heuristic, "random": gt + rng.uniform(-spec.random_offset, spec.random_offset, shape)}
    low, high = np.log(spec.near_offset[0]), np.log(spec.near_offset[1])
    for i in range(spec.near_draws):
        size = np.exp(rng.uniform(low, high, shape))
        targets[f"near{i}"] = gt + np.where(rng.random(shape) < 0.5, -size, size)
    out = {"gt_disparity": gt.astype(np.float32), "gt_confidence": rendered.tile_confidence,
           "gt_spread": rendered.tile_spread, "gt_surfaces": rendered.tile_surfaces.astype(np.float32),
           "measured": measured, "raws": rendered.raws, "black_level": np.int32(rendered.sensor.black_level),
           "scene": np.int32(index)}
    for name, target in targets.items():
        out[f"target_{name}"] = target.astype(np.float32)
        out[f"layers_{name}"] = _layers(processor, frames, target)
    return out


def measurers(spec: DatasetSpec, device: str | None = None):
    """The ``DisparityEngine`` of the spec's size (heuristic targets, frame scaling) and the processor that makes
    the network layers (the engine's own when it correlates as ``spec.correlation()``)."""
    from tpnet_gpu.disparity import DisparityEngine  # noqa: PLC0415 - Warp starts on use
    from tpnet_gpu.processor import TileProcessor  # noqa: PLC0415

    engine = DisparityEngine(spec.height, spec.width, device=device)
    processor = (engine.tp if spec.correlation().resolved(engine.tp.colours) == engine.tp.config else
                 TileProcessor(spec.height, spec.width, config=spec.correlation(), device=device))
    return engine, processor


def remeasure(chunk: dict, target: np.ndarray, engine, processor) -> np.ndarray:
    """Layers ``(ty, tx, 4, 9, 9)`` float16 of a chunk's scene re-measured at ``target (ty, tx)`` from its raw
    frames, scaled and correlated as :func:`build_scene` made them (``engine``, ``processor``: :func:`measurers`)."""
    if "raws" not in chunk:
        raise ValueError("chunk: expected a version-4 chunk with raw frames ('raws'), got one without")
    frames = engine.normalise(chunk["raws"].astype(np.float32) - chunk["black_level"])
    return _layers(processor, frames, np.asarray(target, dtype=np.float32))


def build(folder, spec: DatasetSpec = DatasetSpec(), *, device: str | None = None, progress: bool = True) -> Path:
    """Build the data set into ``folder`` (one NPZ per scene + ``manifest.json``); resumes: chunks already
    present are kept."""
    from tqdm import tqdm  # noqa: PLC0415

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    engine, processor = measurers(spec, device)
    labels = spec.split()
    chunks = []
    for index in tqdm(range(spec.scenes), desc="scenes", disable=not progress):
        path = folder / f"scene_{index:04d}.npz"
        if not path.exists():
            tmp = path.with_suffix(".tmp.npz")
            np.savez_compressed(tmp, **build_scene(index, spec, engine, processor))
            tmp.replace(path)
        chunks.append({"file": path.name, "split": labels[index], "scene": index})
    manifest = {"format": FORMAT, "version": VERSION, "spec": asdict(spec), "variants": list(spec.variants()),
                "chunks": chunks}
    (folder / "manifest.json").write_text(json.dumps(manifest, indent=1))
    return folder


def load(folder, split: str) -> list[dict]:
    """The chunks of one split ('train' or 'test'), each a dict of arrays as written."""
    if split not in ("train", "test"):
        raise ValueError(f"split: expected 'train' or 'test', got {split!r}")
    folder = Path(folder)
    manifest_path = folder / "manifest.json"
    if not manifest_path.exists():
        raise FileNotFoundError(f"{manifest_path}: no data set manifest (build one with `tpnet dataset`)")
    manifest = json.loads(manifest_path.read_text())
    if manifest.get("format") != FORMAT:
        raise ValueError(f"{manifest_path}: expected format {FORMAT!r}, got {manifest.get('format')!r}")
    if manifest.get("version") != VERSION:
        raise ValueError(f"{manifest_path}: expected data set version {VERSION}, got {manifest.get('version')!r} "
                         "(rebuild it with `tpnet dataset`)")
    out = []
    for chunk in manifest["chunks"]:
        if chunk["split"] == split:
            with np.load(folder / chunk["file"]) as data:
                out.append({key: data[key] for key in data.files})
    return out
