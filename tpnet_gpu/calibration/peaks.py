"""The full 2-D peak of each pair correlation (docs/calibration.md §2): whole-lag maximum within ``REACH`` of
the centre, then a parabola through it and its neighbours along each axis. Torch, differentiable with respect
to the correlation values (the maximum's position is piecewise constant), so the gradient calibration uses the
same locator as the LMA one. A parabola pulls sub-lag peaks toward whole lags; calibration iterates to peaks
at lag 0, where that bias vanishes."""

from __future__ import annotations

import torch

REACH = 6  # whole lags searched from the centre (the 15x15 tiles reach 7; the parabola needs one more)


def pair_peaks(corr: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``corr (T, P, S, S)`` (row = vertical lag + S // 2) -> ``(lags (T, P, 2)`` (x, y) px, ``strength (T, P))``;
    NaN lags where the maximum has no curvature (a flat or empty tile)."""
    side = corr.shape[-1]
    r = side // 2
    inner = corr[..., r - REACH : r + REACH + 1, r - REACH : r + REACH + 1]
    flat_inner = inner.reshape(*corr.shape[:-2], -1)
    k = torch.argmax(flat_inner.detach(), dim=-1)  # (T, P)
    iy = k // (2 * REACH + 1) + r - REACH
    ix = k % (2 * REACH + 1) + r - REACH
    flat = corr.reshape(*corr.shape[:-2], -1)

    def at(dy, dx):
        return torch.gather(flat, -1, ((iy + dy) * side + ix + dx)[..., None])[..., 0]

    c0 = at(0, 0)
    lags = []
    ok = torch.ones_like(c0, dtype=torch.bool)
    for dy, dx, i in ((0, 1, ix), (1, 0, iy)):
        minus, plus = at(-dy, -dx), at(dy, dx)
        denom = minus - 2 * c0 + plus
        curved = denom < 0
        frac = 0.5 * (minus - plus) / torch.where(curved, denom, torch.ones_like(denom))
        lags.append(i - r + frac.clamp(-0.5, 0.5))
        ok = ok & curved
    lags = torch.stack(lags, dim=-1)
    return torch.where(ok[..., None], lags, torch.full_like(lags, float("nan"))), c0
