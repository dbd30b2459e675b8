"""Inference with TPNET on the tile processor's output, on the processor's device, without host copies.

The processor's network layers (a torch view of its Warp buffer, ``TileResult.layers``) and the target
disparities go straight into the whole-frame form of the network; the result stays on that device.
"""

from __future__ import annotations

import json
import math
import pickle
from pathlib import Path

import torch

from tpnet_gpu.config import CorrelationConfig, DatasetSpec
from tpnet_gpu.io.paths import regular_file
from tpnet_gpu.net.layers import QUAD_LAGS, lags_match
from tpnet_gpu.net.model import TPNet

WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"
DEFAULT_WEIGHTS = WEIGHTS_DIR / "tpnet_synthetic_v6.pt"


def load(path=None, device=None) -> TPNet:
    """A ``TPNet`` with the weights at ``path`` (default: the shipped quad ones), in eval mode on ``device``; one
    correlation layer per lag of its recipe (:func:`lags`)."""
    path = Path(path) if path is not None else DEFAULT_WEIGHTS
    if not path.exists():
        raise FileNotFoundError(f"{path}: no TPNET weights there (train some with `tpnet train`)")
    model = TPNet(layers=len(lags(path)))
    load_state(model, read_tensors(path, "weights", "TPNET weights"), path, "weights")
    return model.to(device or "cpu").eval()


def read_tensors(path, option: str, what: str, map_location="cpu"):
    """The tensors, numbers, strings, lists and dicts saved at ``path`` by ``torch.save`` - never unpickling
    anything else (``weights_only=True``: a crafted file cannot run code) - or a ``ValueError`` naming ``option``
    and the file (a truncated, crafted or foreign file; a FIFO or a device, which a read would block on), one
    line."""
    regular_file(path, option, "file of " + what)
    try:
        return torch.load(path, map_location=map_location, weights_only=True)
    except (pickle.UnpicklingError, RuntimeError, EOFError, KeyError, TypeError, ValueError, AttributeError,
            IndexError, OverflowError, RecursionError, MemoryError, OSError) as exc:  # OSError: a broken zip
        raise ValueError(f"{option}: {path} is not a file of {what} ({_first_line(exc)})") from exc


def load_state(module, state, path, option: str) -> None:
    """``module.load_state_dict(state)``, a mismatch or a NaN / infinite number (it would make every disparity
    NaN, silently) a ``ValueError`` naming ``option``, the file and the tensor."""
    for name, value in state.items() if isinstance(state, dict) else ():
        if torch.is_tensor(value) and value.is_floating_point() and not bool(torch.isfinite(value).all()):
            raise ValueError(f"{option}: {path} holds NaN or infinite numbers (tensor {str(name)[:80]!r}): not usable "
                             "weights")
    try:
        module.load_state_dict(state)
    except (RuntimeError, KeyError, TypeError, ValueError, AttributeError) as exc:
        raise ValueError(f"{option}: {path} does not hold the expected state ({_first_line(exc)})") from exc


def _first_line(exc: BaseException) -> str:
    """``exc``'s type and the first line of its message (torch's run to several paragraphs), at most 200 chars."""
    text = str(exc).strip()
    return f"{type(exc).__name__}: {(text.splitlines()[0] if text else '')[:200]}"


def recipe(path=None) -> dict:
    """The recipe (command, data set, seed, history) recorded beside the weights."""
    path = Path(path) if path is not None else DEFAULT_WEIGHTS
    where = regular_file(path.with_suffix(".json"), "weights", "recipe file (JSON)")
    try:
        data = json.loads(where.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as exc:
        raise ValueError(f"weights: the recipe {where} beside them is not valid JSON ({type(exc).__name__})") \
            from None
    _check_recipe(data, where)
    return data


def _check_recipe(data, where: Path) -> None:
    """The fields the pipeline reads from a recipe, of the types it reads them as (a crafted or foreign ``.json``
    beside weights is one ``ValueError`` naming the file and the field, not a traceback)."""
    def bad(field: str, expected: str, got) -> ValueError:
        return ValueError(f"weights: the recipe {where}: {field}: expected {expected}, got {str(got)[:80]}")

    def number(v) -> bool:
        return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

    if not isinstance(data, dict):
        raise bad("the file", "a JSON object", type(data).__name__)
    lags_ = data.get("lags", [])
    if not (isinstance(lags_, list) and lags_ and all(isinstance(v, list) and len(v) == 2 and all(map(number, v))
                                                       for v in lags_)) and "lags" in data:
        raise bad("lags", "a list of [x, y] pairs", lags_)
    spec = data.get("dataset_spec", {})
    if not isinstance(spec, dict):
        raise bad("dataset_spec", "an object", spec)
    weights = spec.get("colour_weights", [])
    if weights is not None and not (isinstance(weights, list) and weights and all(map(number, weights))) \
            and "colour_weights" in spec:
        raise bad("dataset_spec.colour_weights", "a list of numbers", weights)
    if "fat_zero" in spec and not number(spec["fat_zero"]):
        raise bad("dataset_spec.fat_zero", "a finite number", spec["fat_zero"])
    if data.get("on_request") is not None and not isinstance(data["on_request"], str):
        raise bad("on_request", "a text", data["on_request"])


def lags(path=None) -> tuple:
    """The layer lags ``((x, y), ...)`` the weights at ``path`` were trained for (their recipe's ``lags``, the
    direction groups of the data set's rig); weights without a recipe, or from before rigs, are the quad's."""
    path = Path(path) if path is not None else DEFAULT_WEIGHTS
    if not path.with_suffix(".json").exists():
        return QUAD_LAGS
    return tuple(tuple(lag) for lag in recipe(path).get("lags", QUAD_LAGS))


def shipped_for(rig_lags, colours: int | None = None, *, requested: bool = False) -> Path | None:
    """The shipped weights (``WEIGHTS_DIR/*.pt``) trained for these layer lags - and, given ``colours``, on frames
    of that many colours (1: mono) - or None: the default quad weights first, then the others by name. Weights
    shipped on request only (``on_request(path)``) count where ``requested`` is True."""
    others = sorted(p for p in WEIGHTS_DIR.glob("*.pt") if p != DEFAULT_WEIGHTS)
    return next((p for p in [DEFAULT_WEIGHTS, *others] if p.exists() and lags_match(lags(p), rig_lags)
                 and (colours is None or fits_colours(p, colours))
                 and (requested or on_request(p) is None)), None)


def on_request(path) -> str | None:
    """Why the weights at ``path`` run only when asked for (``tpnet process --method tpnet``): their recipe's
    ``on_request`` (a measured reason), or None - the pipeline's default for the rig and frames they fit."""
    path = Path(path)
    if not path.with_suffix(".json").exists():
        return None
    reason = recipe(path).get("on_request")
    return None if reason is None else str(reason)


def fits_colours(path, colours: int) -> bool:
    """Whether the weights at ``path`` were trained on frames of ``colours`` colours (weights from before the
    colour record fit any)."""
    trained = correlation(path).colour_weights
    return trained is None or len(trained) == colours


def correlation(path=None):
    """The tile processor's correlation settings the weights at ``path`` were trained on (their recipe's data
    set: colour weights and fat zero); the layers the network reads must be made with these. Weights without
    a recipe are taken to come from today's data set (``DatasetSpec()``)."""
    path = Path(path) if path is not None else DEFAULT_WEIGHTS
    if not path.with_suffix(".json").exists():
        return DatasetSpec().correlation()
    spec = recipe(path).get("dataset_spec", {})
    weights = spec.get("colour_weights")  # absent in data set version 1: the processor's default (as coded)
    return CorrelationConfig(colour_weights=None if weights is None else tuple(weights),
                             fat_zero=spec.get("fat_zero", DatasetSpec().fat_zero))


def infer(model: TPNet, layers: torch.Tensor, target: torch.Tensor, grid: tuple[int, int] | None = None,
          active: torch.Tensor | None = None) -> torch.Tensor:
    """Predicted disparity ``(tiles_y, tiles_x)`` from network layers ``(tiles, G, 9, 9)`` or ``(ty, tx, G, 9, 9)``
    (e.g. ``TileResult.layers``, ``NetworkLayers``) measured at ``target (ty, tx)``; computed on the layers' device,
    no copies (the tiles axis is viewed as the grid)."""
    if layers.dim() == 4:
        if grid is None:
            raise ValueError("grid: expected (tiles_y, tiles_x) for layers of shape (tiles, G, 9, 9), got None")
        layers = layers.view(grid[0], grid[1], *layers.shape[1:])
    with torch.no_grad():
        return target + model.forward_frame(layers, target, active=active)
