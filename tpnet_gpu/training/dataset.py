"""Training and test data for the network: rendered random scenes run through the tile processor.

Per scene (one compressed NPZ chunk) and per target variant, every tile's network layers ``(G, 9, 9)``
(float16; one per direction group of the rig's pairs, ``tpnet_gpu.net.layers``: the quad's 4), its target
disparity, and the ground truth (disparity at the tile centre, confidence, spread). The scenes are rendered with
the spec's rig (``DatasetSpec.rig``, default the quad) and cameras (``cfa``: Bayer, or None for mono; ``photo``:
mono frames made like 8-bit photographs, network.md §14); the manifest keeps the spec and the layer lags.
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
import logging
import os
import tempfile
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import torch

from tpnet_gpu.camera import Rig
from tpnet_gpu.config import DatasetSpec  # noqa: F401 - DatasetSpec re-exported
from tpnet_gpu.scenes import Optics, Sensor, random_scene, render

log = logging.getLogger(__name__)

FORMAT = "tpnet-dataset"
VERSION = 4  # 4: + the raw frames, the engine's measured mask and the window surfaces (re-measuring at new targets)


def spec_rig(spec: DatasetSpec) -> Rig:
    """The rig of ``spec`` at its frame size: ``spec.rig`` (rig-file fields; None: the quad). An ideal rig
    takes the spec's size; a calibrated one must already have it."""
    if spec.rig is None:
        return Rig(width=spec.width, height=spec.height)
    from tpnet_gpu.io.rigfile import rig_from_dict  # noqa: PLC0415 - rigfile imports camera

    rig = rig_from_dict(spec.rig, "spec.rig")
    if rig.is_ideal():
        return replace(rig, width=spec.width, height=spec.height, _cache={})
    if (rig.width, rig.height) != (spec.width, spec.height):
        raise ValueError(f"spec.rig: expected a calibrated rig of the data set's size {spec.width}x{spec.height}, "
                         f"got {rig.width}x{rig.height}")
    return rig


def _layers(engine, processor, layers, frames, target) -> np.ndarray:
    """Network layers ``(tiles_y, tiles_x, G, 9, 9)`` float16 at ``target (tiles_y, tiles_x)``: ``processor``
    loads ``frames`` and is measured there as the engine measures (a calibrated rig's tile centres);
    ``layers`` (``NetworkLayers``) combines its pair correlations."""
    processor.load(frames)
    target_t = torch.as_tensor(np.asarray(target, dtype=np.float32), device=processor.torch_device)
    out = layers.of(engine.measure_at(processor, target_t)).detach().cpu().numpy()
    return out.reshape(target.shape + out.shape[1:]).astype(np.float16)


def build_scene(index: int, spec: DatasetSpec, engine, processor, layers) -> dict:
    """Render scene ``index`` and return its arrays (see the module docstring). ``engine`` (a
    ``DisparityEngine`` of the spec's rig and size) makes the heuristic targets; ``processor`` (correlating as
    ``spec.correlation()``; may be the engine's own) and ``layers`` (its ``NetworkLayers``) the network layers
    (:func:`measurers` makes all three)."""
    rig = spec_rig(spec)
    rng = np.random.default_rng([spec.seed, index])
    scene, seed = random_scene(rig, rng, curved=spec.curved), int(rng.integers(2**31))
    optics = Optics()
    if spec.photo:  # photographs are sharper or blurrier than the renderer's lens: one lens per scene
        from tpnet_gpu.scenes.image_pairs import PhotoFinish, finish_raws, photo_optics  # noqa: PLC0415

        optics = photo_optics(rng)
    rendered = render(scene, rig, optics=optics, sensor=Sensor(cfa=spec.cfa), supersample=spec.supersample,
                      seed=seed)
    raws, black = rendered.raws, rendered.sensor.black_level
    if spec.photo:  # ordinary 8-bit photographs (gamma, JPEG), as image pairs come
        finishes = [PhotoFinish.draw(rng) for _ in range(rig.cams)]
        raws, black = finish_raws(raws, black, rendered.sensor.white_level, finishes), 0
    frames = raws.astype(np.float32) - black
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
           "measured": measured, "raws": raws, "black_level": np.int32(black),
           "scene": np.int32(index)}
    for name, target in targets.items():
        out[f"target_{name}"] = target.astype(np.float32)
        out[f"layers_{name}"] = _layers(engine, processor, layers, frames, target)
    return out


def measurers(spec: DatasetSpec, device: str | None = None):
    """``(engine, processor, layers)``: the ``DisparityEngine`` of the spec's rig and size (heuristic targets,
    frame scaling), the processor that makes the network layers (the engine's own when it correlates as
    ``spec.correlation()``) and its ``NetworkLayers`` (the rig's direction groups)."""
    from tpnet_gpu.disparity import DisparityEngine  # noqa: PLC0415 - Warp starts on use
    from tpnet_gpu.net.layers import NetworkLayers  # noqa: PLC0415 - torch
    from tpnet_gpu.processor import TileProcessor  # noqa: PLC0415

    rig = spec_rig(spec)
    engine = DisparityEngine(spec.height, spec.width, rig=rig, cfa=spec.cfa, device=device)
    tp = engine.tp
    processor = (tp if spec.correlation().resolved(tp.colours) == tp.config else
                 TileProcessor(spec.height, spec.width, camera_offsets=rig.offsets_array(), pairs=tp.pairs,
                               cfa=spec.cfa, config=spec.correlation(), device=device))
    return engine, processor, NetworkLayers(rig.offsets, processor.pairs, processor.torch_device)


def remeasure(chunk: dict, target: np.ndarray, engine, processor, layers) -> np.ndarray:
    """Layers ``(ty, tx, G, 9, 9)`` float16 of a chunk's scene re-measured at ``target (ty, tx)`` from its raw
    frames, scaled and correlated as :func:`build_scene` made them (``engine``, ``processor``, ``layers``:
    :func:`measurers`)."""
    if "raws" not in chunk:
        raise ValueError("chunk: expected a version-4 chunk with raw frames ('raws'), got one without")
    frames = engine.normalise(chunk["raws"].astype(np.float32) - chunk["black_level"])
    return _layers(engine, processor, layers, frames, np.asarray(target, dtype=np.float32))


def chunk_path(folder, index: int) -> Path:
    """Where scene ``index``'s chunk lives in the data set ``folder``."""
    return Path(folder) / f"scene_{index:04d}.npz"


def write_chunk(folder, index: int, spec: DatasetSpec, engine, processor, layers) -> Path:
    """Scene ``index``'s chunk (:func:`build_scene`; ``engine``, ``processor``, ``layers``: :func:`measurers`),
    written whole (a temporary file renamed), unless it is there already (a resumed build). The one writer of
    chunks: the serial build and the Ray workers (``tpnet_gpu.training.ray_jobs``) both call it."""
    path = chunk_path(folder, index)
    if not path.exists():
        handle, tmp = tempfile.mkstemp(prefix=f".{path.stem}.tmp-", suffix=".npz", dir=path.parent)  # unique:
        os.close(handle)  # two workers (two machines on a shared folder) never write one temporary file
        try:
            np.savez_compressed(tmp, **build_scene(index, spec, engine, processor, layers))
        except BaseException:
            os.unlink(tmp)  # a failed or interrupted scene leaves nothing (the build resumes without it)
            raise
        os.replace(tmp, path)
    return path


def write_manifest(folder, spec: DatasetSpec) -> Path:
    """``manifest.json`` of a data set whose chunks are all written: format, spec, variants, the layers' lags (the
    spec rig's direction groups of its default pairs, as :func:`measurers` correlates them) and the chunks."""
    from tpnet_gpu.disparity.pairs import default_pairs  # noqa: PLC0415
    from tpnet_gpu.net.layers import rig_lags  # noqa: PLC0415

    offsets = spec_rig(spec).offsets
    labels = spec.split()
    chunks = [{"file": chunk_path(folder, i).name, "split": labels[i], "scene": i} for i in range(spec.scenes)]
    manifest = {"format": FORMAT, "version": VERSION, "spec": asdict(spec), "variants": list(spec.variants()),
                "lags": [list(lag) for lag in rig_lags(offsets, default_pairs(offsets))], "chunks": chunks}
    path = Path(folder) / "manifest.json"
    path.write_text(json.dumps(manifest, indent=1))
    return path


def build(folder, spec: DatasetSpec = DatasetSpec(), *, device: str | None = None, progress: bool = True,
          chunks=None) -> Path:
    """Build the data set into ``folder`` (one NPZ per scene + ``manifest.json``); resumes: chunks already
    present are kept. ``chunks``: a callable ``(folder, spec, indices, device=, progress=)`` that writes the
    missing scenes' chunks elsewhere - ``ray_jobs.chunk_builder(options)`` spreads them over Ray workers (the
    same chunks, bit for bit) - or None to build them here, one after another."""
    from tpnet_gpu.runtime.progress import bar  # noqa: PLC0415

    folder = Path(folder)  # (a spec of no scenes is refused when it is made: DatasetSpec)
    folder.mkdir(parents=True, exist_ok=True)
    missing = [i for i in range(spec.scenes) if not chunk_path(folder, i).exists()]
    if chunks is not None:
        chunks(folder, spec, missing, device=device, progress=progress)
    elif missing:
        engine, processor, layers = measurers(spec, device)
        for index in bar(missing, desc="scenes", unit="scene", progress=progress):
            log.info("scene %d of %d: %s", index + 1, spec.scenes, write_chunk(folder, index, spec, engine, processor, layers))
    write_manifest(folder, spec)
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
