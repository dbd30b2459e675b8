"""``TPNet``: TPNET as a ``torch.nn.Module`` (network.md §1-4, §8) - the parameters of both stages, the cluster form
for training batches and the whole-frame form for inference, on the functional core of ``net/functional.py``
(conventions there) and the whole-frame form of ``net/frame.py``."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from tpnet_gpu.net.checks import clone_list
from tpnet_gpu.net.frame import frame_residual, stage2_conv
from tpnet_gpu.net.functional import (
    CLONE_RADII, CLUSTER_TILES, CORR_LAYERS, STAGE1_WIDTHS, STAGE2_WIDTHS, Layer, clusters_residual, tensor_version,
    tile_input_count,
)

# ----------------------------------------------------------------------------------------------- module
class TPNet(nn.Module):
    """TPNET with both forms (cluster and whole-frame) on one set of parameters.

    Args:
        layers: correlation layers G per tile, a rig's direction groups (default 4, the quad's): G*81 + 1 inputs.
        stage1_widths: stage-1 layer widths, default ``(256, 128, 32)`` (``NET_ARCH1 = 13``).
        stage2_widths: stage-2 hidden widths, default ``(256, 64, 32, 16)`` (``NET_ARCH2 = 9``); an output
            layer ``16 -> 1`` follows.

    Parameters: Xavier-uniform weights, zero biases (tf-slim defaults). ``stage1[i]`` / ``stage2[i]`` are
    ``nn.Linear``; ``stage2[-1]`` is the output layer (no activation). Default size: 120 480 + 230 529 (224 129
    + 25 x 256 relative-target weights).

    Shape:
        - :meth:`forward_clusters` (= ``forward``): :math:`(B, 25, G \\cdot 81 + 1) \\to (B, 3)` (quad: 325).
        - :meth:`forward_frame`: :math:`(ty, tx, G, 9, 9), (ty, tx) \\to (ty, tx)`.

    >>> net = TPNet()
    >>> net(torch.zeros(2, 25, 325)).shape
    torch.Size([2, 3])
    >>> net.forward_frame(torch.zeros(3, 4, 4, 9, 9), torch.zeros(3, 4)).shape
    torch.Size([3, 4])
    """

    def __init__(self, stage1_widths: Sequence[int] = STAGE1_WIDTHS,
                 stage2_widths: Sequence[int] = STAGE2_WIDTHS, *, layers: int = CORR_LAYERS) -> None:
        super().__init__()
        if isinstance(layers, bool) or not isinstance(layers, int) or layers < 1:
            raise ValueError(f"layers: expected a positive number of correlation layers, got {layers!r}")
        self.layers = layers
        for name, widths in (("stage1_widths", stage1_widths), ("stage2_widths", stage2_widths)):
            if (not isinstance(widths, Sequence) or not widths
                    or not all(isinstance(w, int) and not isinstance(w, bool) and w > 0 for w in widths)):
                raise ValueError(f"{name}: expected a non-empty sequence of positive ints, got {widths!r}")
        self.stage1_widths = tuple(stage1_widths)
        self.stage2_widths = tuple(stage2_widths)
        s1 = (tile_input_count(layers), *self.stage1_widths)
        s2 = (CLUSTER_TILES * (self.stage1_widths[-1] + 1), *self.stage2_widths, 1)
        self.stage1 = nn.ModuleList(nn.Linear(a, b) for a, b in zip(s1[:-1], s1[1:]))
        self.stage2 = nn.ModuleList(nn.Linear(a, b) for a, b in zip(s2[:-1], s2[1:]))
        self._conv, self._conv_key = None, None  # inference's stage-2 kernels and the weights they came from
        self.reset_parameters()

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs):
        """Weights of the layout before the relative targets (stage 2's first layer with 25*F inputs) load with
        zero weights on those inputs, so they give the outputs they were trained to give."""
        key = prefix + "stage2.0.weight"
        old = state_dict.get(key)
        if old is not None and old.shape[1] == CLUSTER_TILES * self.stage1_widths[-1]:
            state_dict[key] = torch.cat([old, old.new_zeros(old.shape[0], CLUSTER_TILES)], dim=1)
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)

    def reset_parameters(self) -> None:
        """Xavier-uniform weights, zero biases."""
        for layer in (*self.stage1, *self.stage2):
            nn.init.xavier_uniform_(layer.weight)
            nn.init.zeros_(layer.bias)

    def extra_repr(self) -> str:
        return f"layers={self.layers}, stage1_widths={self.stage1_widths}, stage2_widths={self.stage2_widths}"

    @property
    def first_layer_weight(self) -> Tensor:
        """Stage 1's first weight :math:`(256, G \\cdot 81 + 1)` (quad: 325), for ``losses.weights_loss``."""
        return self.stage1[0].weight

    def _params(self) -> tuple[list[Layer], list[Layer]]:
        return ([(m.weight, m.bias) for m in self.stage1], [(m.weight, m.bias) for m in self.stage2])

    def forward_clusters(self, x: Tensor) -> Tensor:
        """Residuals :math:`(B, 3)` of the clones ``[5x5, 3x3, 1x1]`` for clusters :math:`(B, 25, 325)`
        (see :func:`clusters_residual`)."""
        return clusters_residual(x, *self._params())

    forward = forward_clusters

    def forward_frame(self, layers: Tensor, target: Tensor, *, grid: tuple[int, int] | None = None,
                      active: Tensor | None = None, clone=0) -> Tensor:
        """Residuals :math:`(ty, tx)` (or :math:`(ty, tx, n)` for a sequence of clones) of a whole frame
        (see ``net.frame.frame_residual``)."""
        stage1, stage2 = self._params()
        conv = None
        if not torch.is_grad_enabled():  # inference: stage 2's kernels are made once per set of weights
            clones = tuple(clone_list(clone, len(CLONE_RADII))[0])
            weight, bias = stage2[0]
            key = (clones, weight.data_ptr(), tensor_version(weight), bias.data_ptr(), tensor_version(bias))
            if self._conv_key != key:
                self._conv, self._conv_key = stage2_conv(stage2[0], clones), key
            conv = self._conv
        return frame_residual(layers, target, stage1, stage2, grid=grid, active=active, clone=clone, conv=conv)

    def predict_frame(self, layers: Tensor, target: Tensor, *, grid: tuple[int, int] | None = None,
                      active: Tensor | None = None, clone=0) -> Tensor:
        """Predicted disparity :math:`(ty, tx)` = target + residual (NaN targets stay NaN).

        Same arguments as :meth:`forward_frame`; a sequence ``clone`` gives :math:`(ty, tx, n)`.
        """
        residual = self.forward_frame(layers, target, grid=grid, active=active, clone=clone)
        ty, tx = residual.shape[:2]
        t = target.reshape(ty, tx)
        return t + residual if residual.dim() == 2 else t.unsqueeze(-1) + residual
