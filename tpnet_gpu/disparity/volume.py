"""Cost volume over absolute disparity bins and its semi-global aggregation over the tile grid.

A volume holds, per tile and disparity bin d_j = d_min + j * step, the combined correlation the tile showed at
d_j in any pass so far (the strongest, where passes overlap). ``aggregate`` runs semi-global matching along 8
grid directions on the cost 1 - correlation: a tile may take its neighbour's disparity for free, a step of one
bin for ``p1`` and any jump for ``p2``, so a weak or periodic tile follows its surface unless its own evidence
is strong. Everything is torch on the volume's device, vectorised over tiles and bins.
"""

from __future__ import annotations

import torch


class CostVolume:
    """``(tiles_y, tiles_x, bins)`` combined correlations over bins ``d_min + j step``; -inf = not measured
    (the identity of the max that merges overlapping passes, so merging is one scatter with no host sync)."""

    def __init__(self, grid: tuple[int, int], d_min: float, d_max: float, step: float, device):
        self.grid, self.step, self.d_min = grid, float(step), float(d_min)
        self.bins = int(round((d_max - d_min) / step)) + 1
        self.values = torch.full((*grid, self.bins), float("-inf"), device=device)
        self.disparities = self.d_min + self.step * torch.arange(self.bins, device=device, dtype=torch.float32)
        # the matching cost and its aggregation, made once: fresh volume-sized arrays (49 MB each at 5 MPix) are
        # page-faulted in anew on every choice (glibc maps blocks over 32 MB per allocation)
        self._cost = torch.empty_like(self.values)
        self._total = torch.empty_like(self.values)

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
        """``(tiles_y, tiles_x, bins)`` matching cost 1 - correlation (clamped to [-1, 1]; 1 where not measured),
        in the volume's own buffer (valid until the next ``cost`` or ``choose``)."""
        # non-finite (not measured: -inf) -> 0 in place: no volume-sized mask
        cost = self._cost.copy_(self.values).nan_to_num_(nan=0.0, posinf=0.0, neginf=0.0)
        return cost.clamp_(-1, 1).neg_().add_(1.0)  # 1 - c, the same rounding

    def choose(self, p1: float, p2: float) -> tuple[torch.Tensor, torch.Tensor]:
        """``pick`` of the SGM aggregation (penalties ``p1``, ``p2``) of the cost: ``(disparity, margin)``
        ``(tiles_y, tiles_x)`` each, with no volume-sized array made."""
        return pick(aggregate(self.cost(), p1, p2, out=self._total), self.disparities, self.step, consume=True)

    def at(self, disparity: torch.Tensor) -> torch.Tensor:
        """The values ``(ty, tx)`` in the bins nearest to ``disparity (ty, tx)`` (NaN where not measured)."""
        j = torch.round((disparity - self.d_min) / self.step).long().clamp(0, self.bins - 1)
        v = torch.gather(self.values, -1, j[..., None])[..., 0]
        return torch.where(torch.isfinite(v), v, torch.full_like(v, float("nan")))


def _walk(cost: torch.Tensor, total: torch.Tensor, dxs: tuple[int, ...], p1: float, p2: float) -> None:
    """Add to ``total`` the SGM path costs L(p, d) = C(p, d) + min(L(q, d), L(q, d +- 1) + p1, min L(q) + p2)
    - min L(q) of the directions (dy, dx) = (+-1, dx) for each dx in ``dxs``, q = p - (dy, dx); ``cost`` and
    ``total`` ``(H, W, D)``. All of them walk the rows together (the dy = -1 ones from the last row): one python
    step per row, not per row and direction.

    Per row the minimum is taken at each predecessor q (its own column) and then moved to p = q + (dy, dx) as it
    is added to the cost; a path entering the grid (first row, or the column a diagonal has no predecessor for)
    starts at its cost. Every buffer and view is made once per walk and written in place (a 5 MPix volume's rows
    are ~1 MB each: a new tensor per operation cost more in allocation than in arithmetic)."""
    height, width, bins = cost.shape
    n = len(dxs)
    lq = cost.new_full((2, n, width, bins + 2), float("inf"))  # (down|up, direction, W, D + 2): L(q), inf beyond
    body = lq[..., 1:-1]  # the bins
    best = cost.new_empty((2, n, width, bins))  # min(...) - min L(q), at q
    low, high = cost.new_empty((2, n, width, 1)), cost.new_empty((2, n, width, 1))  # min L(q), min L(q) + p2
    row_sum = cost.new_empty((width, bins))
    moves = [[], []]  # per walk and direction: views of L(p) with a predecessor, of best there, of L(p) entered
    for m, dx in enumerate(dxs):
        inner = slice(max(dx, 0), width + min(dx, 0))
        source = slice(max(-dx, 0), width - max(dx, 0))
        entered = slice(0, dx) if dx > 0 else slice(width + dx, width)  # empty for dx = 0
        for k in range(2):
            moves[k].append((body[k, m, inner], best[k, m, source], inner, body[k, m, entered], entered))
    for i in range(height):
        if i > 0:
            torch.minimum(lq[..., 2:], lq[..., :-2], out=best)
            best.add_(p1)
            torch.minimum(best, body, out=best)
            torch.amin(body, dim=-1, keepdim=True, out=low)
            torch.minimum(best, torch.add(low, p2, out=high), out=best)
            best.sub_(low)
        for k, row in enumerate((i, height - 1 - i)):
            c, into = cost[row], body[k]
            if i == 0:
                into.copy_(c.expand(n, -1, -1))
            else:
                for into_inner, best_source, inner, into_entered, entered in moves[k]:
                    torch.add(c[inner], best_source, out=into_inner)
                    into_entered.copy_(c[entered])
            # the directions' sum in index order, as a sum over them would add them
            out = total[row]
            if n == 1:
                out += into[0]
            else:
                torch.add(into[0], into[1], out=row_sum)
                for m in range(2, n):
                    row_sum += into[m]
                out += row_sum


def aggregate(cost: torch.Tensor, p1: float, p2: float, out: torch.Tensor | None = None) -> torch.Tensor:
    """Sum ``(H, W, D)`` of the SGM path costs of ``cost (H, W, D)`` along the 8 grid directions: the 6 with a
    vertical step walk the rows, the 2 horizontal ones the rows of the transposed grid (a view: each row of it is
    W rows of D contiguous bins). Written into ``out`` when given (a buffer like ``cost``), else a new array."""
    total = torch.zeros_like(cost) if out is None else out.zero_()
    _walk(cost, total, (-1, 0, 1), p1, p2)
    _walk(cost.transpose(0, 1), total.transpose(0, 1), (0,), p1, p2)
    return total


def pick(aggregated: torch.Tensor, disparities: torch.Tensor, step: float, *,
         consume: bool = False) -> tuple[torch.Tensor, torch.Tensor]:
    """Per tile the disparity of the lowest aggregated cost, refined by a parabola through it and its neighbours,
    and the margin to the lowest cost more than 2 bins away (``(H, W)`` each; larger margin = surer choice).
    ``consume``: ``aggregated`` may be overwritten (its bins near the choice), saving a copy of it."""
    j = torch.argmin(aggregated, dim=-1, keepdim=True)
    bins = aggregated.shape[-1]
    c0 = torch.gather(aggregated, -1, j)
    cm = torch.gather(aggregated, -1, (j - 1).clamp(min=0))
    cp = torch.gather(aggregated, -1, (j + 1).clamp(max=bins - 1))
    denom = cm - 2 * c0 + cp
    frac = torch.where((denom > 0) & (j > 0) & (j < bins - 1), 0.5 * (cm - cp) / denom, torch.zeros_like(denom))
    d = disparities[j[..., 0]] + step * frac[..., 0].clamp(-0.5, 0.5)
    # the bins within 2 of the choice set to inf in one copy (not a volume of int64 distances)
    near = (j + torch.arange(-2, 3, device=aggregated.device)).clamp(0, bins - 1)  # (H, W, 5)
    masked = aggregated.scatter_(-1, near, float("inf")) if consume else aggregated.scatter(-1, near, float("inf"))
    margin = masked.amin(dim=-1) - c0[..., 0]
    return d, margin
