"""Cost volume over absolute disparity bins and its semi-global aggregation over the tile grid.

A volume holds, per tile and disparity bin d_j = d_min + j * step, the combined correlation the tile showed at
d_j in any pass so far (the strongest, where passes overlap). ``aggregate`` runs semi-global matching along 8
grid directions on the cost 1 - correlation: a tile may take its neighbour's disparity for free, a step of one
bin for ``p1`` and any jump for ``p2``, so a weak or periodic tile follows its surface unless its own evidence
is strong. Everything is torch on the volume's device, vectorised over tiles and bins.
"""

from __future__ import annotations

import torch

DIRECTIONS = ((0, 1), (1, 0), (0, -1), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1))  # (dy, dx)


class CostVolume:
    """``(tiles_y, tiles_x, bins)`` combined correlations over bins ``d_min + j step``; -inf = not measured
    (the identity of the max that merges overlapping passes, so merging is one scatter with no host sync)."""

    def __init__(self, grid: tuple[int, int], d_min: float, d_max: float, step: float, device):
        self.grid, self.step, self.d_min = grid, float(step), float(d_min)
        self.bins = int(round((d_max - d_min) / step)) + 1
        self.values = torch.full((*grid, self.bins), float("-inf"), device=device)
        self.disparities = self.d_min + self.step * torch.arange(self.bins, device=device, dtype=torch.float32)

    def reset(self) -> None:
        """Every bin back to not measured (a new frame)."""
        self.values.fill_(float("-inf"))

    def add(self, target: torch.Tensor, offsets: torch.Tensor, combined: torch.Tensor, reach: float,
            tiles: torch.Tensor | None = None) -> None:
        """Put a pass's combined correlations ``(N, E)`` at ``target (N,) + offsets (E,)`` into the bins they hit
        (nearest bin; |offset| <= ``reach``; NaN values and targets are skipped) of the tiles ``tiles`` ``(N,)``
        (flat tile numbers; default all, N = tiles_y * tiles_x); keeps the larger value where a bin was filled."""
        rows = torch.arange(target.numel(), device=target.device) if tiles is None else tiles
        d = target.reshape(-1, 1) + offsets[None, :]
        j = torch.round((torch.nan_to_num(d, nan=self.d_min - self.step) - self.d_min) / self.step)
        ok = (j >= 0) & (j < self.bins) & (offsets.abs()[None, :] <= reach) & torch.isfinite(combined)
        index = rows[:, None] * self.bins + j.clamp(0, self.bins - 1).long()
        source = torch.where(ok, combined, torch.full_like(combined, float("-inf")))
        self.values.view(-1).scatter_reduce_(0, index.reshape(-1), source.reshape(-1), "amax")

    def cost(self) -> torch.Tensor:
        """``(tiles_y, tiles_x, bins)`` matching cost 1 - correlation (clamped to [-1, 1]; 1 where not measured)."""
        return 1.0 - torch.where(torch.isfinite(self.values), self.values, torch.zeros_like(self.values)).clamp(-1, 1)

    def at(self, disparity: torch.Tensor) -> torch.Tensor:
        """The values ``(ty, tx)`` in the bins nearest to ``disparity (ty, tx)`` (NaN where not measured)."""
        j = torch.round((disparity - self.d_min) / self.step).long().clamp(0, self.bins - 1)
        v = torch.gather(self.values, -1, j[..., None])[..., 0]
        return torch.where(torch.isfinite(v), v, torch.full_like(v, float("nan")))


def _path_costs(cost: torch.Tensor, dy: int, dx: int, p1: float, p2: float) -> torch.Tensor:
    """SGM along one direction: L(p, d) = C(p, d) + min(L(q, d), L(q, d +- 1) + p1, min L(q) + p2) - min L(q),
    q = p - (dy, dx); ``cost (H, W, D)``."""
    height, width, _ = cost.shape
    out = torch.empty_like(cost)
    # walk the grid in the direction's order, one line of tiles at a time (rows for dy != 0, else columns)
    if dy != 0:
        order = range(height) if dy > 0 else range(height - 1, -1, -1)
        prev = None
        for y in order:
            c = cost[y]
            if prev is None:
                out[y] = c
            else:
                shifted = torch.full_like(prev, float("inf"))
                if dx > 0:
                    shifted[1:] = prev[:-1]
                elif dx < 0:
                    shifted[:-1] = prev[1:]
                else:
                    shifted = prev
                out[y] = c + _step(shifted, p1, p2)
            prev = out[y]
    else:
        order = range(width) if dx > 0 else range(width - 1, -1, -1)
        prev = None
        for x in order:
            c = cost[:, x]
            out[:, x] = c if prev is None else c + _step(prev, p1, p2)
            prev = out[:, x]
    return out


def _step(prev: torch.Tensor, p1: float, p2: float) -> torch.Tensor:
    """min(L(d), L(d +- 1) + p1, min L + p2) - min L over a line of tiles ``(N, D)`` (inf where no tile)."""
    low = torch.amin(prev, dim=-1, keepdim=True)
    finite = torch.isfinite(low)
    low0 = torch.where(finite, low, torch.zeros_like(low))
    up = torch.cat([prev[:, 1:], torch.full_like(prev[:, :1], float("inf"))], dim=-1)
    down = torch.cat([torch.full_like(prev[:, :1], float("inf")), prev[:, :-1]], dim=-1)
    best = torch.minimum(torch.minimum(prev, torch.minimum(up, down) + p1), low0 + p2)
    return torch.where(finite, best - low0, torch.zeros_like(best))


def aggregate(cost: torch.Tensor, p1: float, p2: float, directions=DIRECTIONS) -> torch.Tensor:
    """Sum of the SGM path costs ``(H, W, D)`` over ``directions``."""
    total = torch.zeros_like(cost)
    for dy, dx in directions:
        total += _path_costs(cost, dy, dx, p1, p2)
    return total


def pick(aggregated: torch.Tensor, disparities: torch.Tensor, step: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Per tile the disparity of the lowest aggregated cost, refined by a parabola through it and its neighbours,
    and the margin to the lowest cost more than 2 bins away (``(H, W)`` each; larger margin = surer choice)."""
    j = torch.argmin(aggregated, dim=-1, keepdim=True)
    bins = aggregated.shape[-1]
    c0 = torch.gather(aggregated, -1, j)
    cm = torch.gather(aggregated, -1, (j - 1).clamp(min=0))
    cp = torch.gather(aggregated, -1, (j + 1).clamp(max=bins - 1))
    denom = cm - 2 * c0 + cp
    frac = torch.where((denom > 0) & (j > 0) & (j < bins - 1), 0.5 * (cm - cp) / denom, torch.zeros_like(denom))
    d = disparities[j[..., 0]] + step * frac[..., 0].clamp(-0.5, 0.5)
    index = torch.arange(bins, device=aggregated.device)
    far = (index[None, None, :] - j).abs() > 2
    margin = torch.where(far, aggregated, torch.full_like(aggregated, float("inf"))).amin(dim=-1) - c0[..., 0]
    return d, margin
