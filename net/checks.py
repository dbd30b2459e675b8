"""Argument checks shared by the network's functional core (net/model.py): tensor metadata only, no host copies."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor


def check_tensor(name: str, x, *, floating: bool = True) -> None:
    if not isinstance(x, Tensor):
        raise TypeError(f"{name}: expected a torch.Tensor, got {type(x).__name__}")
    if floating and not x.is_floating_point():
        raise TypeError(f"{name}: expected a floating-point tensor, got {x.dtype}")


def check_like(name: str, x: Tensor, ref: Tensor, ref_name: str) -> None:
    """``x`` must share ``ref``'s device and dtype."""
    if x.device != ref.device:
        raise ValueError(f"{name}: devices do not match ({x.device} vs {ref.device} of {ref_name})")
    if x.dtype != ref.dtype:
        raise TypeError(f"{name}: expected dtype {ref.dtype} (that of {ref_name}), got {x.dtype}")


def clone_list(clone, count: int) -> tuple[list[int], bool]:
    """Clone indices (each in ``range(count)``) and whether a single one (int) was asked for."""
    single = isinstance(clone, int) and not isinstance(clone, bool)
    clones = [clone] if single else list(clone) if isinstance(clone, Sequence) else None
    if clones is None or not clones or any(
            not isinstance(c, int) or isinstance(c, bool) or c not in range(count) for c in clones):
        raise ValueError(f"clone: expected {', '.join(map(str, range(count)))} or a non-empty sequence of them, "
                         f"got {clone!r}")
    return clones, single


def frame_grid(layers: Tensor, target: Tensor, active: Tensor | None, grid, tile_shape: tuple[int, ...],
               param: Tensor) -> tuple[int, int]:
    """The tile grid ``(ty, tx)`` of a whole-frame call, after checking ``layers`` :math:`(ty, tx, *tile_shape)` or
    :math:`(ty \\cdot tx, *tile_shape)` with ``grid``, ``target`` :math:`(ty, tx)` or :math:`(ty \\cdot tx)`, both
    with ``param``'s dtype and device, and ``active`` :math:`(ty, tx)` bool on their device."""
    shape = ", ".join(map(str, tile_shape))
    check_tensor("layers", layers)
    check_tensor("target", target)
    if grid is not None:
        if (not isinstance(grid, Sequence) or len(grid) != 2
                or not all(isinstance(g, int) and not isinstance(g, bool) and g > 0 for g in grid)):
            raise ValueError(f"grid: expected (tiles_y, tiles_x) of positive ints, got {grid!r}")
        ty, tx = grid
    elif layers.dim() == len(tile_shape) + 2:
        ty, tx = layers.shape[:2]
    else:
        raise ValueError(f"layers: expected shape (ty, tx, {shape}), or (tiles, {shape}) with grid, "
                         f"got {tuple(layers.shape)}")
    if tuple(layers.shape) not in ((ty, tx, *tile_shape), (ty * tx, *tile_shape)):
        raise ValueError(f"layers: expected shape ({ty}, {tx}, {shape}) or ({ty * tx}, {shape}), "
                         f"got {tuple(layers.shape)}")
    if tuple(target.shape) not in ((ty, tx), (ty * tx,)):
        raise ValueError(f"target: expected shape ({ty}, {tx}), got {tuple(target.shape)}")
    check_like("layers", layers, param, "the parameters")
    check_like("target", target, param, "the parameters")
    if active is not None:
        check_tensor("active", active, floating=False)
        if active.dtype != torch.bool:
            raise TypeError(f"active: expected dtype torch.bool, got {active.dtype}")
        if tuple(active.shape) != (ty, tx):
            raise ValueError(f"active: expected shape ({ty}, {tx}), got {tuple(active.shape)}")
        if active.device != layers.device:
            raise ValueError(f"active: devices do not match ({active.device} vs {layers.device} of layers)")
    return ty, tx
