"""TPNET training losses (network.md §2 W-loss, §5): main loss G, mirror ("cut corners") loss S, first-layer
Laplacian regulariser W, and their sum.

All functions are pure torch, keep the inputs' device and never copy to the host. Tiles whose ground truth,
strength or target is NaN get zero weight (network.md ambiguity 7); where every weight is zero a loss is 0
(still attached to the graph, with zero gradients) instead of NaN.

Convention (mirror-loss ring): the 8 neighbours of a tile are in row-major order of the 3x3 square without its
centre, ``RING_OFFSETS`` = (dy, dx) = (-1,-1), (-1,0), (-1,1), (0,-1), (0,1), (1,-1), (1,0), (1,1); in a 5x5
cluster (``k = (dy+2)*5 + (dx+2)``) these are positions ``RING_CLUSTER_INDEX`` = 6, 7, 8, 11, 13, 16, 17, 18.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import torch
import torch.nn.functional as F
from torch import Tensor

CONF_OFFSET = 0.08  # gt_conf_offset
CONF_PWR = 2.0  # gt_conf_pwr
DISP_WMIN = 1.0  # px
DISP_WMAX = 8.0  # px
PARTIAL_WEIGHTS = (2.0, 0.5, 0.2)  # clones 5x5, 3x3, 1x1 (normalised to sum 1 in total_loss)
MIRROR_LAMBDA = 0.1  # SLOSS_LAMBDA
MIRROR_CLIP = 0.2  # SLOSS_CLIP (px)
WEIGHTS_LAMBDA = 0.5  # WLOSS_LAMBDA
DIAGONAL_WEIGHT = 0.7  # neighbour weight of diagonals (orthogonal: 1.0), both in S and W
D_MIN = 0.001  # px, floor of |g - m| in S
RING_OFFSETS = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))
RING_CLUSTER_INDEX = tuple((dy + 2) * 5 + (dx + 2) for dy, dx in RING_OFFSETS)
RING_WEIGHTS = tuple(DIAGONAL_WEIGHT if dy and dx else 1.0 for dy, dx in RING_OFFSETS)
WEIGHTS_MODES = ("as_coded", "isotropic")
CORR_LAYERS = 4  # the quad's correlation layers (a rig's direction groups, tpnet_gpu.net.layers)
CORR_SIDE = 9  # each layer 9x9


# ---------------------------------------------------------------------------------------------- checks
def _check_same(named: dict[str, Tensor], shape_text: str | None = None) -> None:
    """All tensors floating, of the first one's shape and device."""
    (ref_name, ref), *_ = named.items()
    for name, x in named.items():
        if not isinstance(x, Tensor):
            raise TypeError(f"{name}: expected a torch.Tensor, got {type(x).__name__}")
        if not x.is_floating_point():
            raise TypeError(f"{name}: expected a floating-point tensor, got {x.dtype}")
        if x.shape != ref.shape:
            want = shape_text or f"{tuple(ref.shape)} (that of {ref_name})"
            raise ValueError(f"{name}: expected shape {want}, got {tuple(x.shape)}")
        if x.device != ref.device:
            raise ValueError(f"{name}: devices do not match ({x.device} vs {ref.device} of {ref_name})")


def _safe_div(num: Tensor, den: Tensor) -> Tensor:
    """``num / den``, 0 where ``den == 0`` (without NaN in value or gradient)."""
    positive = den > 0
    return torch.where(positive, num, torch.zeros_like(num)) / torch.where(positive, den, torch.ones_like(den))


def _finite(x: Tensor) -> Tensor:
    return x.masked_fill(x.isnan(), 0.0)


# ------------------------------------------------------------------------------------------- main loss
def main_loss(pred: Tensor, gt: Tensor, gt_strength: Tensor, target: Tensor, *, conf_offset: float = CONF_OFFSET,
              conf_pwr: float = CONF_PWR, disp_wmin: float = DISP_WMIN, disp_wmax: float = DISP_WMAX,
              tile_weight: Tensor | None = None) -> Tensor:
    """Main loss G (network.md §5.1, ``batchLoss``): a confidence- and range-weighted MSE.

    .. math::
        w_i = \\max(s_i - \\text{conf\\_offset}, 0)^{\\text{conf\\_pwr}}, \\quad
        k_i = \\frac{\\text{disp\\_wmax}}{\\operatorname{clip}(t_i, \\text{disp\\_wmin}, \\text{disp\\_wmax})},
        \\quad W_i = k_i \\, \\frac{w_i}{\\sum_j w_j} \\, \\tau_i, \\quad
        G = \\sum_i \\frac{W_i}{\\sum_j W_j} (p_i - g_i)^2

    (``tau`` = ``tile_weight``, default 1; the first normalisation cancels in the second, as in the reference).
    Defaults: offset 0.08, power 2, far boost 8 / clip(t, 1, 8) (tiles at <= 1 px weigh 8x those at >= 8 px).

    Args:
        pred: :math:`(*)` predicted disparity ``p`` = target + residual (px), any shape (flattened).
        gt: :math:`(*)` ground-truth disparity ``g``.
        gt_strength: :math:`(*)` ground-truth strength ``s``.
        target: :math:`(*)` target disparity ``t`` (boost uses the target, not the prediction).
        tile_weight: optional :math:`(*)` extra non-negative weights (e.g. hard-case mining).

    Returns:
        Scalar G; 0 when every weight is 0 (tiles with NaN g, s or t weigh 0).

    >>> main_loss(torch.tensor([1.1]), torch.tensor([1.0]), torch.tensor([1.0]), torch.tensor([2.0]))
    tensor(0.0100)
    """
    named = {"pred": pred, "gt": gt, "gt_strength": gt_strength, "target": target}
    if tile_weight is not None:
        named["tile_weight"] = tile_weight
    _check_same(named)
    if not disp_wmin > 0 or not disp_wmax >= disp_wmin:
        raise ValueError(f"disp_wmin, disp_wmax: expected 0 < disp_wmin <= disp_wmax, got {disp_wmin}, {disp_wmax}")
    pred, gt, s, t = pred.flatten(), gt.flatten(), gt_strength.flatten(), target.flatten()
    valid = ~(gt.isnan() | s.isnan() | t.isnan())
    w = torch.clamp(_finite(s) - conf_offset, min=0.0) ** conf_pwr
    k = disp_wmax / torch.clamp(_finite(t), disp_wmin, disp_wmax)
    weight = torch.where(valid, k * _safe_div(w, w.sum()), torch.zeros_like(w))
    if tile_weight is not None:
        weight = weight * _finite(tile_weight.flatten())
    weight = _safe_div(weight, weight.sum())
    err = torch.where(weight > 0, pred - _finite(gt), torch.zeros_like(pred))  # no NaN from weight-0 tiles
    return (weight * err**2).sum()


# ----------------------------------------------------------------------------------------- mirror loss
def mirror_loss(pred: Tensor, gt: Tensor, gt_strength: Tensor, neighbour_gt: Tensor, neighbour_strength: Tensor,
                *, clip: float = MIRROR_CLIP) -> Tensor:
    """Mirror / "cut corners" loss S (network.md §5.2, ``smoothLoss``), cluster form.

    .. math::
        u_j = s_j c_j, \\quad m = \\frac{\\sum_j u_j g_j}{\\sum_j u_j}, \\quad D = \\max(|g - m|, 0.001),
        \\quad \\delta = p - m, \\quad
        \\text{cost} = \\min(\\max(D - \\delta^2 / D, 0), \\text{clip}), \\quad
        S = \\frac{\\sum_b s_b \\, \\text{cost}_b}{\\sum_b s_b}

    with ``c_j`` = 1.0 (orthogonal) / 0.7 (diagonal) neighbours. The cost is an inverted parabola: 0 at
    ``p = g`` and at the mirror ``p = 2m - g``, ``D`` at ``p = m``, 0 outside; i.e. it penalises predictions
    between the ground truth and its mirror about the neighbour mean. Clusters whose neighbour weights sum to
    0 (or with NaN centre g / s) count with weight 0.

    Convention: ``neighbour_*`` in ``RING_OFFSETS`` order (module docstring); from clusters ``(B, 25)`` take
    ``[:, RING_CLUSTER_INDEX]``.

    Args:
        pred: :math:`(B)` predicted disparity of the centre tile (5x5 clone).
        gt, gt_strength: :math:`(B)` centre ground truth and strength.
        neighbour_gt, neighbour_strength: :math:`(B, 8)` ring neighbours' ground truth and strength.
        clip: cost ceiling (px), default 0.2.

    Returns:
        Scalar S.
    """
    _check_same({"pred": pred, "gt": gt, "gt_strength": gt_strength})
    _check_same({"neighbour_gt": neighbour_gt, "neighbour_strength": neighbour_strength})
    if pred.dim() != 1:
        raise ValueError(f"pred: expected shape (B,), got {tuple(pred.shape)}")
    if tuple(neighbour_gt.shape) != (pred.shape[0], len(RING_OFFSETS)):
        raise ValueError(f"neighbour_gt: expected shape ({pred.shape[0]}, 8), got {tuple(neighbour_gt.shape)}")
    if neighbour_gt.device != pred.device:
        raise ValueError(f"neighbour_gt: devices do not match ({neighbour_gt.device} vs {pred.device} of pred)")
    ring = torch.tensor(RING_WEIGHTS, dtype=neighbour_gt.dtype, device=neighbour_gt.device)
    u = torch.where(neighbour_gt.isnan(), torch.zeros_like(neighbour_gt), _finite(neighbour_strength) * ring)
    u_sum = u.sum(dim=1)
    m = _safe_div((u * _finite(neighbour_gt)).sum(dim=1), u_sum)
    s = torch.where((u_sum > 0) & ~gt.isnan(), _finite(gt_strength), torch.zeros_like(gt_strength))
    d = torch.clamp((_finite(gt) - m).abs(), min=D_MIN)
    delta = torch.where(s > 0, pred - m, torch.zeros_like(pred))
    cost = torch.clamp(d - delta**2 / d, min=0.0, max=clip)
    return _safe_div((s * cost).sum(), s.sum())


def ring_neighbours(grid: Tensor) -> Tensor:
    """The 8 ring neighbours of every tile of a :math:`(ty, tx)` grid, edge-replicated: :math:`(ty, tx, 8)`
    in ``RING_OFFSETS`` order."""
    ty, tx = grid.shape
    padded = F.pad(grid[None, None], (1, 1, 1, 1), mode="replicate")[0, 0]
    return torch.stack([padded[1 + dy:1 + dy + ty, 1 + dx:1 + dx + tx] for dy, dx in RING_OFFSETS], dim=-1)


def mirror_loss_frame(pred: Tensor, gt: Tensor, gt_strength: Tensor, *, clip: float = MIRROR_CLIP) -> Tensor:
    """Mirror loss S (see :func:`mirror_loss`) over a dense tile grid, every tile a cluster centre.

    Args:
        pred, gt, gt_strength: :math:`(ty, tx)`; neighbours come from the 3x3 ring with edge replicate
            (= clipped cluster indices).

    Returns:
        Scalar S.
    """
    _check_same({"pred": pred, "gt": gt, "gt_strength": gt_strength}, "(ty, tx) like pred")
    if pred.dim() != 2:
        raise ValueError(f"pred: expected shape (ty, tx), got {tuple(pred.shape)}")
    return mirror_loss(pred.flatten(), gt.flatten(), gt_strength.flatten(),
                       ring_neighbours(gt).flatten(0, 1), ring_neighbours(gt_strength).flatten(0, 1), clip=clip)


# ---------------------------------------------------------------------------------------- weights loss
def weights_loss(first_layer_weight: Tensor, *, mode: str = "as_coded", zero_borders: bool = True,
                 layers: int = CORR_LAYERS) -> Tensor:
    """Laplacian ("smooth weights") regulariser W of stage 1's first layer (network.md §2, ``weightsLoss``).

    Each output unit's ``81 G`` correlation weights (G = ``layers``) are viewed as G maps 9x9, padded by 1 (zeros, or
    edge replicate when ``zero_borders`` is False), and compared with their neighbour average:

    .. math::
        \\text{diff} = w - (a S_\\text{ortho} + b S_\\text{diag}), \\quad a = 1/6.8, \\; b = 0.7/6.8, \\quad
        W_\\text{loss} = \\frac{\\operatorname{mean}_{G \\cdot 81 \\cdot O}(\\text{diff}^2)}
                              {\\operatorname{mean}_{I \\cdot O}(W^2)}

    ``S_diag`` = sum of the 4 diagonal neighbours; ``S_ortho`` = ``2 (left + right)`` in ``"as_coded"`` mode
    (the reference's bug: up/down never used) or ``left + right + up + down`` in ``"isotropic"`` mode. The
    denominator averages over all ``I`` first-layer weights, the target-disparity column (and any other input
    after the layers) included, so the loss is scale-invariant (0 for all-zero weights).

    Convention: ``first_layer_weight`` is ``nn.Linear``'s ``(out, in)`` = ``(O, I)``, inputs
    ``[layer*81 + row*9 + col]`` for the G layers first (columns ``0 .. 81 G - 1``), then the target and any other
    inputs (TF stores ``[in, out]``); row = up/down, col = left/right.

    Args:
        first_layer_weight: :math:`(O, I)`, ``I > 81 G`` (the quad's TPNET: ``(256, 325)``).
        mode: ``"as_coded"`` (default, parity) or ``"isotropic"``.
        zero_borders: zero padding (default, ``WBORDERS_ZERO``) or edge replicate.
        layers: G, the correlation layers the first inputs hold (default 4, the quad's; ``TPNet.layers``).

    Returns:
        Scalar W_loss.
    """
    w = first_layer_weight
    if not isinstance(w, Tensor) or not w.is_floating_point():
        raise TypeError(f"first_layer_weight: expected a floating-point tensor, got "
                        f"{w.dtype if isinstance(w, Tensor) else type(w).__name__}")
    if isinstance(layers, bool) or not isinstance(layers, int) or layers < 1:
        raise ValueError(f"layers: expected a positive number of correlation layers, got {layers!r}")
    cells = layers * CORR_SIDE * CORR_SIDE
    if w.dim() != 2 or w.shape[1] <= cells:
        raise ValueError(f"first_layer_weight: expected shape (out, > {cells}) for {layers} layers and the target, "
                         f"got {tuple(w.shape)}")
    if mode not in WEIGHTS_MODES:
        raise ValueError(f"mode: expected one of {WEIGHTS_MODES}, got {mode!r}")
    maps = w[:, :cells].reshape(w.shape[0], layers, CORR_SIDE, CORR_SIDE)  # (O, G, 9, 9): the layers' columns
    if zero_borders:
        p = F.pad(maps, (1, 1, 1, 1))
    else:
        p = F.pad(maps, (1, 1, 1, 1), mode="replicate")
    left, right = p[..., 1:-1, :-2], p[..., 1:-1, 2:]
    up, down = p[..., :-2, 1:-1], p[..., 2:, 1:-1]
    diag = p[..., :-2, :-2] + p[..., :-2, 2:] + p[..., 2:, :-2] + p[..., 2:, 2:]
    ortho = 2 * (left + right) if mode == "as_coded" else left + right + up + down
    norm = 4 * (1 + DIAGONAL_WEIGHT)  # 6.8: the kernel sums to 1
    diff = maps - (ortho / norm + DIAGONAL_WEIGHT * diag / norm)
    return _safe_div((diff**2).mean(), (w**2).mean())


# ----------------------------------------------------------------------------------------------- total
class LossTerms(NamedTuple):
    """``total`` = sum_n pi_n ``main[n]`` + mirror_lambda ``mirror`` + weights_lambda ``weights``."""

    total: Tensor  # scalar
    main: Tensor  # (n,) G per clone
    mirror: Tensor  # scalar S (clone 0)
    weights: Tensor  # scalar W_loss


def total_loss(residual: Tensor, target: Tensor, gt: Tensor, gt_strength: Tensor, first_layer_weight: Tensor, *,
               neighbour_gt: Tensor | None = None, neighbour_strength: Tensor | None = None,
               partial_weights: Sequence[float] = PARTIAL_WEIGHTS, mirror_lambda: float = MIRROR_LAMBDA,
               weights_lambda: float = WEIGHTS_LAMBDA, mirror_clip: float = MIRROR_CLIP,
               weights_mode: str = "as_coded", zero_borders: bool = True, tile_weight: Tensor | None = None,
               conf_offset: float = CONF_OFFSET, conf_pwr: float = CONF_PWR, disp_wmin: float = DISP_WMIN,
               disp_wmax: float = DISP_WMAX, layers: int = CORR_LAYERS) -> LossTerms:
    """Total training loss (network.md §5.3):

    .. math::
        L = \\sum_n \\pi_n G_n + \\lambda_S S + \\lambda_W W_\\text{loss}, \\quad
        \\pi = \\text{partial\\_weights} / \\sum \\text{partial\\_weights}

    Defaults: ``pi`` = [2, 0.5, 0.2] / 2.7 = [0.7407, 0.1852, 0.0741], ``lambda_S`` = 0.1, ``lambda_W`` = 0.5;
    ``G_n`` on clone n's prediction ``t + residual[..., n]`` (NaN targets enter as 0, weight 0), S on clone 0.

    Two forms (clone axis last in both, as the model returns it):

    * cluster: ``residual`` :math:`(B, n)` (:meth:`TPNet.forward_clusters`), centre ``target``, ``gt``,
      ``gt_strength`` :math:`(B)`, ``neighbour_gt`` / ``neighbour_strength`` :math:`(B, 8)` (ring order);
    * frame: ``residual`` :math:`(ty, tx, n)` (:meth:`TPNet.forward_frame` with ``clone=(0, 1, 2)``),
      the rest :math:`(ty, tx)`, no neighbours (S via :func:`mirror_loss_frame`).

    Args:
        first_layer_weight: :math:`(O, I)` (``TPNet.first_layer_weight``; the quad's ``(256, 325)``).
        layers: G, the correlation layers the weight reads first (``TPNet.layers``), for W.
        tile_weight: optional extra per-tile weights for G (shape of ``target``).
        Other keywords: see :func:`main_loss`, :func:`mirror_loss`, :func:`weights_loss`.

    Returns:
        :class:`LossTerms` (total, per-clone G, S, W_loss).
    """
    if not isinstance(residual, Tensor) or residual.dim() < 2:
        raise ValueError(f"residual: expected a tensor of shape (B, n) or (ty, tx, n), got "
                         f"{tuple(residual.shape) if isinstance(residual, Tensor) else type(residual).__name__}")
    if len(partial_weights) != residual.shape[-1]:
        raise ValueError(f"partial_weights: expected {residual.shape[-1]} weights (one per clone of residual), "
                         f"got {len(partial_weights)}")
    if (neighbour_gt is None) != (neighbour_strength is None):
        raise ValueError("neighbour_gt, neighbour_strength: expected both or neither, got one")
    cluster = neighbour_gt is not None
    if not cluster and residual.dim() != 3:
        raise ValueError(f"residual: expected shape (ty, tx, n) without neighbours (frame form), "
                         f"got {tuple(residual.shape)}")
    _check_same({"target": target, "gt": gt, "gt_strength": gt_strength},
                f"{tuple(residual.shape[:-1])} (residual without its clone axis)")
    if target.shape != residual.shape[:-1]:
        raise ValueError(f"target: expected shape {tuple(residual.shape[:-1])} (residual without its clone axis), "
                         f"got {tuple(target.shape)}")
    pred = _finite(target).unsqueeze(-1) + residual
    kwargs = dict(conf_offset=conf_offset, conf_pwr=conf_pwr, disp_wmin=disp_wmin, disp_wmax=disp_wmax,
                  tile_weight=tile_weight)
    main = torch.stack([main_loss(pred[..., n], gt, gt_strength, target, **kwargs)
                        for n in range(residual.shape[-1])])
    pi = torch.tensor(partial_weights, dtype=main.dtype, device=main.device)
    pi = pi / pi.sum()
    if cluster:
        mirror = mirror_loss(pred[..., 0], gt, gt_strength, neighbour_gt, neighbour_strength, clip=mirror_clip)
    else:
        mirror = mirror_loss_frame(pred[..., 0], gt, gt_strength, clip=mirror_clip)
    weights = weights_loss(first_layer_weight, mode=weights_mode, zero_borders=zero_borders, layers=layers)
    total = (pi * main).sum() + mirror_lambda * mirror + weights_lambda * weights
    return LossTerms(total, main, mirror, weights)
