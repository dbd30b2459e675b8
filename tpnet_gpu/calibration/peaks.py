"""The full 2-D peak of each pair correlation (docs/calibration.md §2): whole-lag maximum within ``REACH`` of
the centre, then a parabola through the logarithms of it and its neighbours along each axis (exact for a
Gaussian peak, which the low-passed phase correlation resembles; the plain values where a neighbour is not
positive). Torch, differentiable with respect
to the correlation values (the maximum's position is piecewise constant), so the gradient calibration uses the
same locator as the LMA one. A parabola through the plain values pulls sub-lag peaks toward whole lags (a
peak 0.4 lag off read ~0.3: calibration rounds converged at half the pace); calibration iterates to peaks at
lag 0, where either has no bias."""

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
        positive = (minus > 0) & (plus > 0) & (c0 > 0)
        tiny = torch.finfo(corr.dtype).tiny  # keeps the unused log branch finite (no NaN in the backward pass)
        minus, centre, plus = (torch.where(positive, torch.log(v.clamp(min=tiny)), v) for v in (minus, c0, plus))
        denom = minus - 2 * centre + plus
        curved = denom < 0
        frac = 0.5 * (minus - plus) / torch.where(curved, denom, torch.ones_like(denom))
        lags.append(i - r + frac.clamp(-0.5, 0.5))
        ok = ok & curved
    lags = torch.stack(lags, dim=-1)
    return torch.where(ok[..., None], lags, torch.full_like(lags, float("nan"))), c0
