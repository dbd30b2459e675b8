"""TPNET's whole-frame form (network.md §3): stage 1 as a matmul over every tile of a frame (a 1x1 convolution),
stage 2's first layer as a 5x5 convolution over replicate-padded stage-1 features plus a matmul over each tile's
25 relative targets, the rest per tile - the same parameters and outputs as the cluster form of net/model.py,
whose per-tile pieces (inputs, stage 1, stage 2's rest, clone masks) it uses. Conventions: net/model.py.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torch import Tensor

from tpnet_gpu.net.checks import clone_list, frame_grid
from tpnet_gpu.net.functional import (
    CLONE_RADII, CLUSTER_SIDE, CLUSTER_TILES, CORR_SIZE, NEGATIVE_SLOPE, Layer, check_layers, clone_masks,
    stage1_features, stage2_output, tile_inputs,
)
from tpnet_gpu.net.neighbours import CLUSTER_RADIUS, frame_relative_targets

# Tiles per step of the whole-frame stage 1 (``frame_stage1``) and stage 2 (``frame_stage2``, whole grid rows):
# bounds their temporaries - at 5 MPix stage 1's inputs and first layer for all 78408 tiles at once are ~180 MB,
# stage 2's hidden layer 80 MB and a copy of it: most of a frame's peak memory above the buffers.
STEP_TILES = 16384


def stage2_conv(first: Layer, clones: Sequence[int]) -> tuple[Tensor, Tensor, Tensor]:
    """Stage 2's first layer, one masked copy per clone, as 5x5 convolution kernels :math:`(n \\cdot hidden, F, 5, 5)`
    (``kernel[o, c, dy+2, dx+2] = W[o, k*F + c]``), relative-target weights :math:`(n \\cdot hidden, 25)`
    (``W[o, 25*F + k]``) and biases :math:`(n \\cdot hidden)`."""
    weight, bias = first
    hidden = weight.shape[0]
    n_features = weight.shape[1] // CLUSTER_TILES - 1
    kernel = weight[:, :CLUSTER_TILES * n_features].reshape(hidden, CLUSTER_TILES, n_features).transpose(1, 2)
    kernel = kernel.reshape(hidden, n_features, CLUSTER_SIDE, CLUSTER_SIDE)
    masks = clone_masks(weight.device, weight.dtype)[list(clones)]  # (n, 5, 5)
    relative = weight[:, CLUSTER_TILES * n_features:].unsqueeze(0) * masks.flatten(1)[:, None]  # (n, hidden, 25)
    return ((kernel.unsqueeze(0) * masks[:, None, None]).flatten(0, 1), relative.flatten(0, 1),
            bias.repeat(len(clones)))


def frame_stage1(layers: Tensor, target: Tensor, stage1: Sequence[Layer], *, steps: bool = True) -> Tensor:
    """Stage 1 of every tile of a frame, ``STEP_TILES`` tiles at a time (the same rows as all at once), or all at
    once without ``steps``.

    Args:
        layers: :math:`(ty, tx, G, 9, 9)` correlation layers; target: :math:`(ty, tx)` target disparities.

    Returns:
        :math:`(ty, tx, F)` features.
    """
    ty, tx = target.shape
    if not steps or ty * tx <= STEP_TILES:
        return stage1_features(tile_inputs(layers, target), stage1)
    layers, target = layers.reshape(ty * tx, *layers.shape[2:]), target.reshape(-1)
    features = layers.new_empty((ty * tx, stage1[-1][0].shape[0]))
    for start in range(0, ty * tx, STEP_TILES):
        rows = slice(start, start + STEP_TILES)
        features[rows] = stage1_features(tile_inputs(layers[rows], target[rows]), stage1)
    return features.view(ty, tx, -1)


def frame_residual(layers: Tensor, target: Tensor, stage1: Sequence[Layer], stage2: Sequence[Layer], *,
                   grid: tuple[int, int] | None = None, active: Tensor | None = None, clone=0,
                   conv: tuple[Tensor, Tensor, Tensor] | None = None, steps: bool = True) -> Tensor:
    """Whole-frame form: residual disparity of every tile, by convolutions with the cluster form's weights.

    Args:
        layers: :math:`(ty, tx, G, 9, 9)`, or :math:`(ty \\cdot tx, G, 9, 9)` (row-major tiles) with ``grid``;
            G = the layers the weights read (the quad's 4).
        target: :math:`(ty, tx)` (or :math:`(ty \\cdot tx)` with ``grid``) target disparities; NaN -> 0.
        stage1, stage2: ``(weight, bias)`` pairs (see :class:`TPNet`).
        grid: ``(ty, tx)``, required for tile-major ``layers``.
        active: optional :math:`(ty, tx)` bool; inactive tiles get zero stage-1 features.
        clone: 0, 1 or 2 (5x5, 3x3, centre-only stage 2), or a sequence of them (stage 1 runs once).
        conv: ``stage2_conv(stage2[0], clones)`` when the caller keeps it (else made here).
        steps: stage 1 and stage 2 in steps of ``STEP_TILES`` tiles (the same values, less memory); False: the
            whole frame at once (what ``torch.export`` can trace with the tile counts symbolic, net/export.py).

    Returns:
        :math:`(ty, tx)` residuals for an int ``clone``; :math:`(ty, tx, n)` for a sequence of ``n`` clones
        (clone axis last, as in the cluster form). On the inputs' device.

    Raises:
        TypeError / ValueError: bad shapes, dtypes (inputs must have the parameters' dtype, ``active`` bool),
        devices that differ, or a bad ``clone``.
    """
    g = check_layers(stage1, stage2)
    clones, single = clone_list(clone, len(CLONE_RADII))
    tile_shape = (g, CORR_SIZE, CORR_SIZE)
    ty, tx = frame_grid(layers, target, active, grid, tile_shape, stage1[0][0])

    features = frame_stage1(layers.reshape(ty, tx, *tile_shape), target.reshape(ty, tx), stage1,
                            steps=steps)  # (ty, tx, F)
    if active is not None:
        features = torch.where(active.unsqueeze(-1), features, torch.zeros_like(features))
    residual = frame_stage2(features, target.reshape(ty, tx), stage2, clones, active=active, conv=conv, steps=steps)
    return residual[..., 0] if single else residual


def frame_stage2(features: Tensor, target: Tensor, stage2: Sequence[Layer], clones: Sequence[int], *,
                 active: Tensor | None = None, conv: tuple[Tensor, Tensor, Tensor] | None = None,
                 steps: bool = True) -> Tensor:
    """Stage 2 of the whole-frame form: 5x5 convolution over replicate-padded stage-1 features plus the relative
    targets' term, then the per-tile rest. Arguments as :func:`frame_residual` (checked there).

    Args:
        features: :math:`(ty, tx, F)` stage-1 features (zero on inactive tiles).
        target: :math:`(ty, tx)` target disparities (px).

    Returns:
        :math:`(ty, tx, n)` residuals of the ``n`` clones.
    """
    ty, tx = target.shape
    padded = F.pad(features.permute(2, 0, 1).unsqueeze(0), (CLUSTER_RADIUS,) * 4, mode="replicate")
    hidden, n = stage2[0][0].shape[0], len(clones)
    kernels, relative_weight, biases = conv if conv is not None else stage2_conv(stage2[0], clones)
    relative = frame_relative_targets(target, active)  # (ty*tx, 25)

    def grid_rows(start, stop) -> Tensor:
        """``(stop - start, tx, n)``: the residuals of grid rows start..stop-1 (the convolution reads 2 more rows
        on each side of them)."""
        z = F.conv2d(padded[:, :, start:stop + 2 * CLUSTER_RADIUS], kernels, biases)  # (1, n*hidden, rows, tx)
        z.view(n * hidden, -1).addmm_(relative_weight, relative[start * tx:stop * tx].T)  # in place
        z = z.view(n, hidden, stop - start, tx).permute(2, 3, 0, 1)  # (rows, tx, n, hidden)
        return z.squeeze(-1) if len(stage2) == 1 else stage2_output(F.leaky_relu(z, NEGATIVE_SLOPE, inplace=True),
                                                                    stage2[1:])

    rows = max(1, STEP_TILES // tx)  # grid rows per step
    if not steps or rows >= ty:  # no python loop over the rows: torch.export keeps ty symbolic
        return grid_rows(0, ty)
    out = features.new_empty((ty, tx, n))
    for start in range(0, ty, rows):
        out[start:start + rows] = grid_rows(start, min(ty, start + rows))
    return out
