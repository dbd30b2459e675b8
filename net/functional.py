"""TPNET's functional core (network.md §1-4, §8): the two-stage disparity network as functions of its parameters;
``net/model.py`` wraps them in the ``TPNet`` module and ``net/frame.py`` builds the whole-frame form on them.

Stage 1 (per tile, shared by every tile) maps the tile's 4 correlation layers and its target disparity
(325 values) to 32 features; stage 2 combines the features of a 5x5 tile cluster and the cluster's targets
relative to the centre's (800 + 25 values) into the **residual** disparity of the centre tile (predicted
disparity = target + residual). Two equivalent forms use the same parameters:

* cluster form (training batches): ``(B, 25, 325) -> (B, 3)``, one output per stage-2 clone (§4);
* whole-frame form (inference, dense training; net/frame.py): stage 1 as a matmul over all tiles (a 1x1
  convolution), stage 2's first layer as a 5x5 convolution over replicate-padded stage-1 features plus a matmul
  over each tile's 25 relative targets, the rest per tile.

Convention:
    * Correlation layers are ordered ``[hor, vert, diag-main, diag-other]``; each is 9x9 (row = vertical
      shift, col = horizontal shift, -4..+4 px). A tile's input is the layers flattened layer-major then
      row-major (``layer*81 + row*9 + col``), then the target disparity: 325 values. NaN inputs become 0.
    * Cluster position ``k = (dy+2)*5 + (dx+2)`` (row-major, centre ``k = 12``); stage 2's input is
      ``[k*32 + c]`` then ``[800 + k]`` = clip(target_k - target_centre, +-2 px), 0 where either target is NaN
      (or, in the frame form, the neighbour inactive); weights of the older layout without these inputs load
      with zero columns there (the same outputs). The equivalent 5x5 kernel is
      ``kernel[o, c, dy+2, dx+2] = W[o, k*32 + c]`` (``nn.Linear`` stores ``W`` as ``(out, in)``).
    * Clones: 0 = all 5x5 positions, 1 = inner 3x3, 2 = centre only; positions outside a clone's square
      feed zero features to the shared stage 2.
    * Frame edges replicate the edge tiles' stage-1 features (= cluster indices clipped to the frame);
      inactive tiles (``active`` False) have zero stage-1 features, also where replicated.

Nothing here copies to the host: shapes, dtypes and devices are checked from tensor metadata only.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from tpnet_gpu.net.checks import check_like, check_tensor, clone_list
from tpnet_gpu.net.neighbours import CLUSTER_RADIUS, relative_targets

CORR_LAYERS = 4  # the quad's layers: hor, vert, diag-main, diag-other (other rigs: one per direction group)
CORR_SIZE = 9  # 9x9 crop per layer
CORR_CELLS = CORR_SIZE * CORR_SIZE  # 81 inputs per layer


def tile_input_count(layers: int = CORR_LAYERS) -> int:
    """Stage-1 inputs of a tile with ``layers`` correlation layers: ``layers * 81`` + the target (quad: 325)."""
    return layers * CORR_CELLS + 1


CLUSTER_SIDE = 2 * CLUSTER_RADIUS + 1  # 5
CLUSTER_TILES = CLUSTER_SIDE * CLUSTER_SIDE  # 25
CENTRE = CLUSTER_TILES // 2  # 12
CLONE_RADII = tuple(range(CLUSTER_RADIUS, -1, -1))  # (2, 1, 0): clone n keeps max(|dy|, |dx|) <= CLONE_RADII[n]
NEGATIVE_SLOPE = 0.2  # LeakyReLU as coded: max(0.2 x, x)
STAGE1_WIDTHS = (256, 128, 32)
STAGE2_WIDTHS = (256, 64, 32, 16)

Layer = tuple[Tensor, Tensor]  # (weight (out, in), bias (out,)) as in nn.Linear


# ---------------------------------------------------------------------------------------------- checks
def check_layers(stage1: Sequence[Layer], stage2: Sequence[Layer]) -> int:
    if len(stage1) < 1 or len(stage2) < 1:
        raise ValueError(f"stage1/stage2: expected at least one layer each, got {len(stage1)} and {len(stage2)}")
    inputs = stage1[0][0].shape[1]
    if inputs < tile_input_count(1) or (inputs - 1) % CORR_CELLS:
        raise ValueError(f"stage1: expected a first layer of G*81 + 1 inputs (quad: 325), got {inputs}")
    features = stage1[-1][0].shape[0]
    if stage2[0][0].shape[1] != CLUSTER_TILES * (features + 1):
        raise ValueError(f"stage2: expected a first layer with {CLUSTER_TILES}*{features} + {CLUSTER_TILES} inputs, "
                         f"got {stage2[0][0].shape[1]}")
    if stage2[-1][0].shape[0] != 1:
        raise ValueError(f"stage2: expected a last layer with 1 output, got {stage2[-1][0].shape[0]}")
    return (inputs - 1) // CORR_CELLS  # G, the correlation layers stage 1 reads


# ----------------------------------------------------------------------------------------- functional
def tile_inputs(layers: Tensor, target: Tensor) -> Tensor:
    """Stage-1 input vectors of tiles: flattened correlation layers then target disparity, NaN -> 0.

    Args:
        layers: :math:`(..., G, 9, 9)` correlation layers (the quad's ``[hor, vert, diag-main, diag-other]``).
        target: :math:`(...)` target disparities (px), same leading shape, dtype and device.

    Returns:
        :math:`(..., G \\cdot 81 + 1)` with ``[layer*81 + row*9 + col]`` then the target (index 324 for G = 4).

    >>> tile_inputs(torch.zeros(2, 25, 4, 9, 9), torch.ones(2, 25)).shape
    torch.Size([2, 25, 325])
    """
    check_tensor("layers", layers)
    check_tensor("target", target)
    if layers.dim() < 3 or tuple(layers.shape[-2:]) != (CORR_SIZE, CORR_SIZE):
        raise ValueError(f"layers: expected shape (..., G, 9, 9), got {tuple(layers.shape)}")
    if target.shape != layers.shape[:-3]:
        raise ValueError(f"target: expected shape {tuple(layers.shape[:-3])} (the leading shape of layers), "
                         f"got {tuple(target.shape)}")
    check_like("target", target, layers, "layers")
    x = torch.cat([layers.flatten(-3), target.unsqueeze(-1)], dim=-1)
    return x.masked_fill_(x.isnan(), 0.0)  # in place: x is cat's new tensor


def gather_clusters(tile_map: Tensor, tile_y: Tensor, tile_x: Tensor) -> Tensor:
    """5x5 clusters around centre tiles, neighbour indices clipped to the frame (= edge replicate).

    Args:
        tile_map: :math:`(ty, tx, ...)` any per-tile values (e.g. :func:`tile_inputs` ``(ty, tx, 325)``).
        tile_y, tile_x: :math:`(B)` integer centre coordinates, on ``tile_map``'s device.

    Returns:
        :math:`(B, 25, ...)` in cluster order ``k = (dy+2)*5 + (dx+2)``.

    >>> gather_clusters(torch.zeros(3, 4, 325), torch.tensor([0, 2]), torch.tensor([3, 1])).shape
    torch.Size([2, 25, 325])
    """
    check_tensor("tile_map", tile_map, floating=False)
    if tile_map.dim() < 2:
        raise ValueError(f"tile_map: expected shape (ty, tx, ...), got {tuple(tile_map.shape)}")
    for name, idx in (("tile_y", tile_y), ("tile_x", tile_x)):
        check_tensor(name, idx, floating=False)
        if idx.is_floating_point() or idx.is_complex() or idx.dtype == torch.bool:
            raise TypeError(f"{name}: expected an integer tensor, got {idx.dtype}")
        if idx.dim() != 1 or idx.shape != tile_y.shape:
            raise ValueError(f"{name}: expected shape (B,) like tile_y, got {tuple(idx.shape)}")
        if idx.device != tile_map.device:
            raise ValueError(f"{name}: devices do not match ({idx.device} vs {tile_map.device} of tile_map)")
    ty, tx = tile_map.shape[:2]
    d = torch.arange(-CLUSTER_RADIUS, CLUSTER_RADIUS + 1, device=tile_map.device)
    ys = (tile_y[:, None, None] + d[None, :, None]).clamp(0, ty - 1)  # (B, 5, 1)
    xs = (tile_x[:, None, None] + d[None, None, :]).clamp(0, tx - 1)  # (B, 1, 5)
    return tile_map[ys, xs].flatten(1, 2)


def stage1_features(x: Tensor, stage1: Sequence[Layer]) -> Tensor:
    """Stage 1 on tile inputs: Linear + LeakyReLU(0.2) for every layer, the last included.

    Args:
        x: :math:`(..., 325)` tile inputs (NaN-free, see :func:`tile_inputs`).
        stage1: ``(weight, bias)`` pairs, ``weight`` :math:`(out, in)`.

    Returns:
        :math:`(..., F)` features, ``F`` = last layer's width (32).
    """
    for weight, bias in stage1:
        x = F.leaky_relu(F.linear(x, weight, bias), NEGATIVE_SLOPE, inplace=True)  # in place on linear's output
    return x


def stage2_output(z: Tensor, stage2: Sequence[Layer]) -> Tensor:
    """Stage 2 after its input: LeakyReLU(0.2) after each layer but the last (the 1-wide output).

    Args:
        z: :math:`(..., H)` input of ``stage2[0]`` (``H = 800`` for the cluster form).
        stage2: ``(weight, bias)`` pairs, the last with one output.

    Returns:
        :math:`(...)` residual disparities.
    """
    for i, (weight, bias) in enumerate(stage2):
        z = F.linear(z, weight, bias)
        if i < len(stage2) - 1:
            z = F.leaky_relu(z, NEGATIVE_SLOPE)
    return z.squeeze(-1)


def clone_masks(device=None, dtype=torch.float32) -> Tensor:
    """The three clone masks :math:`(3, 5, 5)` (1 inside, 0 outside), built on ``device`` (no host copy).

    >>> clone_masks().sum(dim=(1, 2)).tolist()
    [25.0, 9.0, 1.0]
    """
    d = torch.arange(-CLUSTER_RADIUS, CLUSTER_RADIUS + 1, device=device).abs()
    cheb = torch.maximum(d[:, None], d[None, :])
    radii = CLUSTER_RADIUS - torch.arange(len(CLONE_RADII), device=device)  # = CLONE_RADII, made on the device
    return (cheb[None] <= radii[:, None, None]).to(dtype)


def clusters_residual(x: Tensor, stage1: Sequence[Layer], stage2: Sequence[Layer]) -> Tensor:
    """Cluster form: residual disparity of each cluster's centre tile for the three clones.

    Args:
        x: :math:`(B, 25, 325)` tile inputs in cluster order ``k = (dy+2)*5 + (dx+2)``; NaN -> 0.
        stage1, stage2: ``(weight, bias)`` pairs (see :class:`TPNet`).

    Returns:
        :math:`(B, 3)` residuals of clones ``[5x5, inner 3x3, centre only]``.

    Raises:
        TypeError / ValueError: ``x`` not a float tensor of shape (B, 25, 325), or not on the parameters'
        device / dtype.
    """
    check_layers(stage1, stage2)
    check_tensor("x", x)
    if x.dim() != 3 or tuple(x.shape[1:]) != (CLUSTER_TILES, stage1[0][0].shape[1]):
        raise ValueError(f"x: expected shape (B, {CLUSTER_TILES}, {stage1[0][0].shape[1]}), got {tuple(x.shape)}")
    check_like("x", x, stage1[0][0], "the parameters")
    features = stage1_features(x.masked_fill(x.isnan(), 0.0), stage1)  # (B, 25, F)
    relative = relative_targets(x[..., -1], x[:, CENTRE, -1:])  # (B, 25), from the targets before NaN -> 0
    masks = clone_masks(x.device, x.dtype).reshape(len(CLONE_RADII), 1, CLUSTER_TILES)  # (3, 1, 25)
    z = torch.cat([(features.unsqueeze(0) * masks.unsqueeze(-1)).flatten(2),
                   relative.unsqueeze(0) * masks], dim=-1)  # (3, B, 25*F + 25): [k*F + c], then [25*F + k]
    return stage2_output(z, stage2).transpose(0, 1)  # (B, 3)


def tensor_version(t: Tensor) -> int:
    """``t``'s in-place version (inference tensors, e.g. weights loaded under ``torch.inference_mode``, keep none)."""
    return -1 if t.is_inference() else t._version
