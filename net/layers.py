"""The network's correlation layers for any rig (network.md §11): one 9x9 layer per direction group of pairs.

``NetworkLayers`` is made once per rig (its camera offsets and pairs); it owns the index tables on the device and
turns the tile processor's pair correlations ``(tiles, P, 15, 15)`` into layers ``(tiles, G, 9, 9)``, one per
direction group (``tpnet_gpu.disparity.pairs.direction_groups``: pairs of the same lag vector, opposite lags
mirrored). A group's layer is the centre 9x9 crop of its pairs combined as the quad's kernel combines two
(``kernels/correlate.py`` ``combine``, network.md §1), generalised to n pairs:

* one pair: its correlation as it is;
* n >= 2 pairs: ``(prod_i (c_i + o))^(1/n) - o`` where every ``c_i > 0``, else 0 (``o < 0``: the plain mean).

For the quad this is the processor's own ``TileResult.layers`` [hor, vert, diag-main, diag-other], bit for bit
(float32 sums and products, the root in float64 rounded once: tests/net/test_layers.py).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from tpnet_gpu import tables
from tpnet_gpu.disparity.pairs import LAG_TOLERANCE, DirectionGroup, default_pairs, direction_groups
from tpnet_gpu.layout import CORR_SIDE, NET_CROP, NET_SIDE


def rig_lags(offsets, pairs=None) -> tuple:
    """The layer lags ``((x, y), ...)`` of a rig's direction groups (``pairs`` default: the rig's default pairs,
    ``default_pairs``): what weights trained for the rig record and what a pipeline must match."""
    return tuple(g.lag for g in direction_groups(offsets, default_pairs(offsets) if pairs is None else pairs))


QUAD_LAGS = rig_lags(tables.QUAD_OFFSETS)  # ((1, 0), (0, 1), (1, 1), (1, -1)): hor, vert, diag-main, diag-other


def lags_match(first, second) -> bool:
    """Whether two lists of layer lags are the same layers (same order, each within ``LAG_TOLERANCE``)."""
    a, b = np.asarray(first, dtype=np.float64).reshape(-1, 2), np.asarray(second, dtype=np.float64).reshape(-1, 2)
    return a.shape == b.shape and bool(np.all(np.abs(a - b) <= LAG_TOLERANCE))


def _gather_index(groups: tuple[DirectionGroup, ...], members: int) -> np.ndarray:
    """``(G, members, 81)`` flat indices into a tile's ``(P, 15, 15)`` correlations: the centre 9x9 of each
    member pair, point-mirrored for mirrored members; 0 in unused member slots."""
    crop = np.arange(NET_SIDE) + NET_CROP
    index = np.zeros((len(groups), members, NET_SIDE * NET_SIDE), dtype=np.int64)
    for g, group in enumerate(groups):
        for m, (pair, mirrored) in enumerate(group.members):
            rows = crop[::-1] if mirrored else crop  # mirrored lag: (y, x) -> (-y, -x) about the centre 7
            index[g, m] = (pair * CORR_SIDE * CORR_SIDE + rows[:, None] * CORR_SIDE + rows[None, :]).reshape(-1)
    return index


class NetworkLayers:
    """Per-tile network layers of one rig from its pair correlations.

    Args:
        offsets: ``(cams, 2)`` camera offsets in baselines (``Rig.offsets``).
        pairs: ``(P, 2)`` the correlated pairs, in the processor's order (``TileProcessor.pairs``).
        device: where the correlations live (torch device or name).
        offset: the combination's offset o (default ``tables.NET_CORR_OFFSET`` = 0.1; < 0: the plain mean).

    Attributes:
        groups: the direction groups (their ``lag`` vectors name the layers, in layer order).
        count: ``G``, the number of layers.

    Shape:
        - :meth:`__call__`: :math:`(tiles, P, 15, 15) \\to (tiles, G, 9, 9)`.

    >>> NetworkLayers(tables.QUAD_OFFSETS, tables.QUAD_PAIRS, "cpu")(torch.zeros(3, 6, 15, 15)).shape
    torch.Size([3, 4, 9, 9])
    """

    def __init__(self, offsets, pairs, device="cpu", *, offset: float = tables.NET_CORR_OFFSET):
        self.groups = direction_groups(offsets, pairs)
        self.pairs = len(tuple(pairs))
        self.count = len(self.groups)
        self.offset = float(offset)
        self.device = torch.device(device)
        sizes = [len(g.members) for g in self.groups]
        members = max(sizes)
        self._index = torch.as_tensor(_gather_index(self.groups, members).reshape(-1), device=self.device)
        used = np.arange(members)[None, :] < np.array(sizes)[:, None]  # (G, members)
        self._unused = torch.as_tensor(~used, device=self.device)[:, :, None]  # (G, members, 1)
        self._sizes = torch.as_tensor(sizes, device=self.device)[:, None]  # (G, 1)
        self._members = members

    @property
    def lags(self) -> tuple:
        """The layers' lag vectors ``((x, y), ...)`` in layer order (see :func:`rig_lags`)."""
        return tuple(g.lag for g in self.groups)

    def of(self, result) -> Tensor:
        """Layers :math:`(tiles, G, 9, 9)` of a processor pass (``TileResult``): the processor's own (its quad
        kernel, equal to this object's) where it made them, else from its correlations."""
        own = result.layers is not None and result.layers.shape[1] == self.count
        return result.layers if own else self(result.corr)

    def __call__(self, corr: Tensor) -> Tensor:
        """Layers :math:`(tiles, G, 9, 9)` from pair correlations :math:`(tiles, P, 15, 15)` (``TileResult.corr``),
        on their device, in their dtype."""
        if not isinstance(corr, Tensor) or not corr.is_floating_point():
            raise TypeError(f"corr: expected a floating-point torch.Tensor, got "
                            f"{corr.dtype if isinstance(corr, Tensor) else type(corr).__name__}")
        if corr.dim() != 4 or tuple(corr.shape[1:]) != (self.pairs, CORR_SIDE, CORR_SIDE):
            raise ValueError(f"corr: expected shape (tiles, {self.pairs}, {CORR_SIDE}, {CORR_SIDE}), "
                             f"got {tuple(corr.shape)}")
        if corr.device != self.device and not (corr.device.type == self.device.type == "cuda"
                                               and self.device.index is None):
            raise ValueError(f"corr: devices do not match ({corr.device} vs {self.device} of the layers' tables)")
        tiles = corr.shape[0]
        values = corr.reshape(tiles, -1).index_select(1, self._index)
        values = values.view(tiles, self.count, self._members, NET_SIDE * NET_SIDE)  # (T, G, M, 81)
        if self.offset < 0:  # the plain mean over the members
            mean = values.masked_fill(self._unused, 0.0).sum(dim=2) / self._sizes
            return mean.view(tiles, self.count, NET_SIDE, NET_SIDE)
        positive = (values > 0) | self._unused
        shifted = (values + self.offset).masked_fill(self._unused, 1.0)  # unused slots multiply by 1
        product = shifted[:, :, 0]  # (T, G, 81); multiplied member by member: torch's prod() reduces in
        for m in range(1, self._members):  # float64 on the CPU, the kernel in float32
            product = product * shifted[:, :, m]
        # the root in float64, rounded once to float32: torch's float32 sqrt on the CPU is not correctly rounded
        # (0.038450133 -> 0.19608706, the kernel's IEEE sqrt 0.19608705); sqrt for two pairs, the n-th root else
        wide = product.double()
        root = torch.where(self._sizes == 2, wide.sqrt(), wide.pow(1.0 / self._sizes)).to(values.dtype)
        combined = torch.where(positive.all(dim=2), root - self.offset, torch.zeros_like(root))
        single = (self._sizes == 1)  # one pair: its correlation as it is (the quad's diagonals)
        out = torch.where(single, values[:, :, 0], combined)
        return out.view(tiles, self.count, NET_SIDE, NET_SIDE)
