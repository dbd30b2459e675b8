"""Training TPNET on data sets built by ``tpnet dataset`` (network.md §4-§7, scaled to our data size).

Dense training: every sample is one scene's whole tile grid and one target variant (heuristic, random, near);
the network runs in its whole-frame form (stage 1 once per tile, stage 2 as a 5x5 convolution), so all 5x5
clusters of a frame share their stage-1 work. Per tile the loss weights follow §5 (ground-truth confidence,
far-range boost), tiles whose target is more than ``max_offset`` px from the ground truth are left out, and
hard cases (relative 5x5 ground-truth spread >= 0.4, §6) get half of every batch's weight, and each error is
scaled by c / (|target - gt| + c) (``error_scale`` c; ours, not the original's).
Loss = sum_n pi_n G_n (clones 5x5, 3x3, 1x1) + 0.1 S (mirror) + 0.5 W (first-layer Laplacian).
"""

from __future__ import annotations

import json
import logging
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from tpnet_gpu.config import TrainConfig  # noqa: F401 - re-exported: the training settings live in config
from tpnet_gpu.net import infer
from tpnet_gpu.net.layers import QUAD_LAGS, lags_match, rig_lags
from tpnet_gpu.net.losses import main_loss, mirror_loss_frame, weights_loss
from tpnet_gpu.net.model import TPNet
from tpnet_gpu.outputs.folder import output_file

_log = logging.getLogger(__name__)

PARTIAL_WEIGHTS = (2.0, 0.5, 0.2)
LR_STEPS = ((0.0, 3e-4), (0.15, 1e-4), (0.3, 3e-5), (0.6, 1e-5), (0.9, 3e-6))  # (fraction of epochs, lr), §7


def learning_rate(epoch: int, epochs: int, start: float = 0.0) -> float:
    """The rate of ``epoch`` of ``epochs``: ``LR_STEPS`` scaled to the run, entered at fraction ``start``."""
    frac = start + (1.0 - start) * epoch / max(epochs, 1)
    return [lr for start, lr in LR_STEPS if frac >= start][-1]


def relative_spread(gt: np.ndarray) -> np.ndarray:
    """5x5 max - min of the ground truth, scaled by 5 / max where max >= 5 (network.md §6), ``(ty, tx)``."""
    padded = np.pad(gt, 2, mode="edge")
    windows = np.lib.stride_tricks.sliding_window_view(padded, (5, 5))
    hi, lo = windows.max(axis=(-2, -1)), windows.min(axis=(-2, -1))
    v = hi - lo
    return np.where(hi >= 5.0, v * 5.0 / np.maximum(hi, 1e-9), v)


def frame_samples(chunks: list[dict], variants, device="cpu") -> list[dict]:
    """One sample per (chunk, variant): tensors layers (ty, tx, 4, 9, 9), target, gt, strength, hard-case mask,
    on ``device`` (the whole data set is small enough to live there)."""
    samples = []
    for chunk in chunks:
        missing = [v for v in variants if f"layers_{v}" not in chunk]
        if missing:
            raise ValueError(f"variants: the data set has no {missing} targets (it holds "
                             f"{sorted(k[7:] for k in chunk if k.startswith('layers_'))}); rebuild it or choose others")
        gt = chunk["gt_disparity"].astype(np.float32)
        hard = relative_spread(gt) >= 0.4
        for variant in variants:
            target = chunk[f"target_{variant}"].astype(np.float32)
            samples.append({
                "layers": torch.from_numpy(np.nan_to_num(chunk[f"layers_{variant}"].astype(np.float32))).to(device),
                "target": torch.from_numpy(np.nan_to_num(target)).to(device),
                "gt": torch.from_numpy(gt).to(device),
                "strength": torch.from_numpy(chunk["gt_confidence"].astype(np.float32)).to(device),
                "hard": torch.from_numpy(hard).to(device),
                "scene": int(chunk["scene"]),
                "variant": variant,
            })
    return samples


def refresh_passes(model: TPNet, samples: list[dict], chunks: list[dict], measure, targets=None) -> list:
    """The "pass" samples: per chunk, the model's prediction from its heuristic sample (or the given ``targets``,
    a resumed run's), with layers re-measured there by ``measure(chunk, target) -> (ty, tx, 4, 9, 9)``.
    Returns the targets ``(ty, tx)`` float32 per chunk (a checkpoint keeps them)."""
    heuristic = {s["scene"]: s for s in samples if s["variant"] == "heuristic"}
    new_samples, new_targets = [], []
    for i, chunk in enumerate(chunks):
        h = heuristic[int(chunk["scene"])]
        if targets is None:
            with torch.no_grad():
                t = (h["target"] + model.forward_frame(h["layers"], h["target"])).cpu().numpy()
        else:
            t = targets[i]
        layers = measure(chunk, t)
        sample = {**h, "variant": "pass", "target": torch.from_numpy(np.nan_to_num(t)).to(h["target"].device),
                  "layers": torch.from_numpy(np.nan_to_num(layers.astype(np.float32))).to(h["layers"].device)}
        new_samples.append(sample)
        new_targets.append(t.astype(np.float32))
    samples[:] = [s for s in samples if s["variant"] != "pass"] + new_samples  # replaced, in chunk order, last
    return new_targets


def _tile_weights(sample: dict, config: TrainConfig) -> torch.Tensor:
    """Per-tile extra weight: 0 off-target (|t - g| > max_offset) or on the frame border; hard/easy balanced."""
    usable = (sample["target"] - sample["gt"]).abs() <= config.max_offset
    usable[:1], usable[-1:], usable[:, :1], usable[:, -1:] = False, False, False, False
    hard = sample["hard"] & usable
    easy = ~sample["hard"] & usable
    w = torch.zeros_like(sample["target"])
    n_hard, n_easy = int(hard.sum()), int(easy.sum())
    if n_hard and n_easy:
        w[hard] = config.hard_share / n_hard
        w[easy] = (1 - config.hard_share) / n_easy
    elif n_hard or n_easy:
        w[hard | easy] = 1.0 / (n_hard + n_easy)
    return w


def sample_loss(model: TPNet, sample: dict, config: TrainConfig) -> torch.Tensor:
    tile_w = _tile_weights(sample, config)
    pi = [w / sum(PARTIAL_WEIGHTS) for w in PARTIAL_WEIGHTS]
    residual = model.forward_frame(sample["layers"], sample["target"], clone=(0, 1, 2))  # (ty, tx, 3)
    loss = 0.0
    gt = sample["gt"]
    scale = 1.0 if config.error_scale is None else config.error_scale / (
        (sample["target"] - gt).abs().nan_to_num(0.0) + config.error_scale)
    for clone in range(3):
        pred = sample["target"] + residual[..., clone]
        scaled = gt + (pred - gt) * scale  # main_loss then sees the scaled error
        loss = loss + pi[clone] * main_loss(scaled, gt, sample["strength"], sample["target"], tile_weight=tile_w)
    full = sample["target"] + residual[..., 0]
    mirror = mirror_loss_frame(full, sample["gt"], sample["strength"] * (tile_w > 0))
    return loss + config.mirror_lambda * mirror


def evaluate(model: TPNet, samples: list[dict], *, max_offset: float = 2.0, min_strength: float = 0.5) -> dict:
    """RMSE of the network and of its input targets on the tiles with strength >= ``min_strength``, finite
    ground truth, |target - gt| <= ``max_offset``, off the border."""
    net_err, tgt_err = [], []
    with torch.no_grad():
        for s in samples:
            pred = s["target"] + model.forward_frame(s["layers"], s["target"])
            sel = (s["strength"] >= min_strength) & ((s["target"] - s["gt"]).abs() <= max_offset)
            sel[:1], sel[-1:], sel[:, :1], sel[:, -1:] = False, False, False, False
            net_err.append((pred - s["gt"])[sel])
            tgt_err.append((s["target"] - s["gt"])[sel])
    net = torch.cat(net_err) if net_err else torch.zeros(0)
    tgt = torch.cat(tgt_err) if tgt_err else torch.zeros(0)
    rmse = lambda e: float(torch.sqrt(torch.mean(e**2))) if e.numel() else float("nan")  # noqa: E731
    return {"tiles": int(net.numel()), "rmse_network": rmse(net), "rmse_target": rmse(tgt)}


def data_lags(manifest: dict) -> tuple:
    """The layer lags of a data set (its manifest's ``lags``; data sets from before rigs: the quad's)."""
    return tuple(tuple(lag) for lag in manifest.get("lags", QUAD_LAGS))


def train(data_folder, out_path, config: TrainConfig = TrainConfig(), *, checkpoint=None, progress: bool = True,
          log=_log.info, stop_after: int | None = None, device: str = "cpu", rig=None) -> dict:
    """Train from scratch, or resume from ``checkpoint`` (a path written by this function); writes the final
    weights (state dict + recipe JSON beside it) to ``out_path``. ``stop_after`` ends the run after that
    epoch as an interruption would (the checkpoint then resumes it). ``device``: where the data and the model
    live (runs are bit-reproducible on the CPU). The network has one layer per direction group of the data
    set's rig; ``rig`` (a ``Rig``), when given, must have the data set's layer lags. Returns the history."""
    previous = torch.are_deterministic_algorithms_enabled()
    torch.use_deterministic_algorithms(True, warn_only=str(device) != "cpu")  # CUDA: some ops lack one
    try:
        return _train(data_folder, out_path, config, checkpoint=checkpoint, progress=progress, log=log,
                      stop_after=stop_after, device=device, rig=rig)
    finally:
        torch.use_deterministic_algorithms(previous)


def _train(data_folder, out_path, config: TrainConfig, *, checkpoint, progress: bool, log, stop_after, device,
           rig) -> dict:
    from tpnet_gpu.training import dataset  # noqa: PLC0415
    from tpnet_gpu.runtime.progress import bar as progress_bar  # noqa: PLC0415

    torch.manual_seed(config.seed)
    manifest = json.loads((Path(data_folder) / "manifest.json").read_text())
    lags = data_lags(manifest)
    if rig is not None and not lags_match(rig_lags(rig.offsets), lags):
        raise ValueError(f"rig: the data set {data_folder} was rendered with a rig of layer lags "
                         f"{[list(v) for v in lags]}; the given rig's are {[list(v) for v in rig_lags(rig.offsets)]} "
                         f"(train it on a data set of that rig, `tpnet dataset --rig`)")
    train_chunks = dataset.load(data_folder, "train")
    train_samples = frame_samples(train_chunks, config.variants, device)
    test_samples = frame_samples(dataset.load(data_folder, "test"), ("heuristic",), device)
    if not train_samples:
        raise ValueError(f"{data_folder}: the data set has no training scenes")
    model = TPNet(layers=len(lags))
    if config.init is not None:  # fine-tuning: start from these weights (a checkpoint still takes precedence)
        if not Path(config.init).exists():
            raise FileNotFoundError(f"init: {config.init}: no weights there")
        infer.load_state(model, infer.read_tensors(config.init, "init", "TPNET weights"), config.init, "init")
    model = model.to(device)
    optimiser = torch.optim.Adam(model.parameters(), lr=LR_STEPS[0][1])
    start_epoch, history, pass_targets = 0, [], None
    checkpoint = Path(checkpoint) if checkpoint else None
    if checkpoint is not None and checkpoint.exists():
        # tensors and plain data only: a crafted checkpoint cannot run code (issue 40)
        state = infer.read_tensors(checkpoint, "checkpoint", "a training checkpoint", map_location=device)
        if not isinstance(state, dict) or not {"model", "optimiser", "epoch", "history"} <= set(state):
            raise ValueError(f"checkpoint: {checkpoint} is not a training checkpoint (expected the keys model, "
                             "optimiser, epoch, history)")
        infer.load_state(model, state["model"], checkpoint, "checkpoint")
        infer.load_state(optimiser, state["optimiser"], checkpoint, "checkpoint")
        start_epoch, history = state["epoch"], state["history"]
        pass_targets = state.get("pass_targets")
        pass_targets = None if pass_targets is None else [torch.as_tensor(t).cpu().numpy() for t in pass_targets]
        log(f"resumed from {checkpoint} at epoch {start_epoch}")
    measure = None
    n_samples = len(train_samples) + (len(train_chunks) if config.pass_every is not None else 0)
    if config.pass_every is not None:
        spec = dataset.DatasetSpec(**{k: tuple(v) if isinstance(v, list) else v for k, v in manifest["spec"].items()})
        measurers = dataset.measurers(spec, device)
        measure = lambda chunk, t: dataset.remeasure(chunk, t, *measurers)  # noqa: E731
        if pass_targets is not None:  # resumed between refreshes: the same pass samples as the unbroken run
            refresh_passes(model, train_samples, train_chunks, measure, pass_targets)
    rng = np.random.default_rng(config.seed)
    for _ in range(start_epoch):  # replay the shuffles so a resumed run is identical to an unbroken one
        rng.permutation(n_samples)
    last = config.epochs if stop_after is None else min(stop_after, config.epochs)
    bar = progress_bar(range(start_epoch, last), desc="epochs", unit="epoch", progress=progress)
    for epoch in bar:
        for group in optimiser.param_groups:
            group["lr"] = learning_rate(epoch, config.epochs, config.lr_from)
        if measure is not None and epoch % config.pass_every == 0:
            pass_targets = refresh_passes(model, train_samples, train_chunks, measure)
        order = rng.permutation(len(train_samples))
        total = 0.0
        for first in range(0, len(order), config.batch):
            optimiser.zero_grad()
            batch = [train_samples[i] for i in order[first : first + config.batch]]
            weights = {**dict(zip(config.variants, config.variant_weights)), "pass": 1.0}
            loss = sum(weights[s["variant"]] * sample_loss(model, s, config) for s in batch) / len(batch)
            loss = loss + config.weights_lambda * weights_loss(model.stage1[0].weight, mode=config.w_mode, layers=model.layers)
            loss.backward()
            optimiser.step()
            total += float(loss.detach()) * len(batch)
        record = {"epoch": epoch + 1, "loss": total / len(order), "lr": learning_rate(epoch, config.epochs, config.lr_from),
                  **{f"test_{k}": v for k, v in evaluate(model, test_samples).items()}}
        history.append(record)
        bar.set_postfix(loss=f"{record['loss']:.4f}", rmse=f"{record['test_rmse_network']:.4f}")
        log(f"epoch {record['epoch']}: loss {record['loss']:.5f}, test RMSE {record['test_rmse_network']:.4f} px")
        if checkpoint is not None:  # whole or not at all: a run killed while saving keeps the last checkpoint
            with output_file(checkpoint, overwrite=True, option="checkpoint") as tmp:
                torch.save({"model": model.state_dict(), "optimiser": optimiser.state_dict(), "epoch": epoch + 1,
                            "history": history, "config": asdict(config),
                            # as tensors: the checkpoint is read back with weights_only (no NumPy pickles)
                            "pass_targets": None if pass_targets is None else [torch.from_numpy(t) for t in
                                                                               pass_targets]}, tmp)
    rig_arg = "" if manifest["spec"].get("rig") is None else f" --rig {_rig_argument(manifest['spec']['rig'])}"
    mono_arg = (" --mono" if "cfa" in manifest["spec"] and manifest["spec"]["cfa"] is None else "") + (
        " --photo" if manifest["spec"].get("photo") else "")
    recipe = {"command": f"tpnet dataset {data_folder} --scenes {manifest['spec']['scenes']}{rig_arg}{mono_arg} && "
                         f"tpnet train {data_folder}{rig_arg} --epochs {config.epochs} --batch {config.batch} "
                         f"--seed {config.seed} "
                         f"--error-scale {config.error_scale or 0} --random-weight "
                         f"{dict(zip(config.variants, config.variant_weights)).get('random', 1.0)}"
                         + (f" --init {config.init} --lr-from {config.lr_from}" if config.init else "")
                         + (f" --pass-every {config.pass_every}" if config.pass_every else ""),
              "config": asdict(config), "data": str(data_folder), "dataset_spec": manifest["spec"],
              "rig": manifest["spec"].get("rig"), "lags": [list(lag) for lag in lags], "history": history}
    if config.init is not None:  # the recipe of the weights this run started from, so the chain is on record
        init_recipe = Path(config.init).with_suffix(".json")
        recipe["init_recipe"] = json.loads(init_recipe.read_text()) if init_recipe.exists() else None
    save_weights(model, out_path, recipe)
    return {"history": history}


def _rig_argument(rig: dict) -> str:
    """``--rig`` for a data set's rig: the shipped example it is (at any size, when ideal), else the recipe's."""
    from tpnet_gpu.io import rigfile  # noqa: PLC0415

    size = ("width", "height")
    for name, path in rigfile.examples().items():
        example = rigfile.rig_to_dict(rigfile.read_rig(path))
        if {k: v for k, v in example.items() if k not in size} == {k: v for k, v in rig.items() if k not in size}:
            return name
    return "RIG.json (the recipe's \"rig\", written as a rig file)"


def save_weights(model: TPNet, path, recipe: dict) -> Path:
    """Write the state dict (``path``) and its recipe (``path`` with ``.json``), each whole or not at all
    (``outputs.output_file``; replacing what is there: ``tpnet train`` asks for ``--overwrite`` first)."""
    path = Path(path)
    with output_file(path, overwrite=True, option="out") as tmp:
        torch.save({k: v.cpu() for k, v in model.state_dict().items()}, tmp)
    with output_file(path.with_suffix(".json"), overwrite=True, option="out") as tmp:
        tmp.write_text(json.dumps(recipe, indent=1, default=str))
    return path
