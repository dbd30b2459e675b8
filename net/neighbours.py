"""Stage 2's relative-target inputs (network.md §3): each tile of a 5x5 cluster contributes its target disparity
minus the centre tile's, clipped, so stage 2 sees the local depth structure the engine's targets already hold.

Nothing here copies to the host.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor

CLUSTER_RADIUS = 2  # stage 2 reads 5x5 tile clusters (model.py imports it from here)
# Neighbour targets relative to the centre's enter stage 2 clipped: a neighbour on another surface reads as "far",
# not as its distance (fine-tuning experiments, network.md §10: flat tiles 0.70x -> 0.64x of the engine's RMSE).
NEIGHBOUR_CLIP = 2.0  # px


def relative_targets(neighbours: Tensor, centre: Tensor) -> Tensor:
    """Stage 2's target inputs: ``clip(neighbours - centre, +-NEIGHBOUR_CLIP)``, 0 where either is NaN.

    Args:
        neighbours: :math:`(..., 25)` targets of a cluster (px), cluster order.
        centre: :math:`(..., 1)` the centre tile's target (px).

    Returns:
        :math:`(..., 25)` relative targets.

    >>> relative_targets(torch.tensor([[0.5, 9.0, float("nan")]]), torch.tensor([[1.0]])).tolist()
    [[-0.5, 2.0, 0.0]]
    """
    return (neighbours - centre).nan_to_num_(0.0).clamp_(-NEIGHBOUR_CLIP, NEIGHBOUR_CLIP)  # in place: a new tensor


def frame_relative_targets(target: Tensor, active: Tensor | None = None) -> Tensor:
    """Every tile's 25 relative targets (:func:`relative_targets`) over its 5x5 cluster, edge tiles replicated.

    Args:
        target: :math:`(ty, tx)` target disparities (px).
        active: optional :math:`(ty, tx)` bool; inactive tiles read as NaN (relative target 0).

    Returns:
        :math:`(ty \\cdot tx, 25)` in cluster order ``k = (dy+2)*5 + (dx+2)``, tiles row-major.
    """
    ty, tx = target.shape
    t = target if active is None else torch.where(active, target, torch.full_like(target, float("nan")))
    side = 2 * CLUSTER_RADIUS + 1
    padded = F.pad(t.reshape(1, 1, ty, tx), (CLUSTER_RADIUS,) * 4, mode="replicate")[0, 0]  # (ty + 4, tx + 4)
    neighbours = padded.unfold(0, side, 1).unfold(1, side, 1)  # (ty, tx, 5, 5) view: [y, x, dy+2, dx+2]
    return relative_targets(neighbours, t[:, :, None, None]).reshape(ty * tx, side * side)  # order k
