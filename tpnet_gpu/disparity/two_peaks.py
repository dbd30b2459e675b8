"""Two peaks in one lobe: does a tile's correlation hold two given surfaces? (motion_and_surfaces.md §4; used by
``two_surface``).

An edge tile's surfaces are mostly 1-4 px apart while one surface's peak along a pair's axis is ~3 px wide (the
Bayer green-only phase correlation): the two peaks merge into one lobe with a shoulder and no second maximum.
Each pair's axis profile is modelled as ``a1 S_p(e - d1) + a2 S_p(e - d2)``, the amplitudes shared by the pairs
(a surface's share of the window is the same for every pair). ``S_p``, the tile's own single-surface peak along
pair p's axis, is read off the correlations of the pairs perpendicular to p (``cut_plan``): every pair sees the
same 2-D peak shape of the window's texture, and a spread of disparities moves a pair's peaks along its own axis
only, so a perpendicular pair's correlation cut along p's axis, through its peaks, has the shape without the
spread (texture-dependent widths included: a frame-wide median shape explained flat tiles' profiles by two peaks
nearly as often as edge tiles'). For fixed ``(d1, d2)`` the amplitudes are a 2x2 linear least-squares problem,
so ``LobeFit`` scores every pair of candidate positions on a ``SHAPE_STEP`` grid at once (variable projection).
The tile shows both surfaces when the best pair with each peak within ``radius`` of its expected depth explains
the profiles nearly as well as or better than the best one-surface model (one shape, or two at most
``ONE_SURFACE`` apart: a fractional position, a slightly wider peak) - residual ratio >= ``min_gain`` - with both
amplitudes positive and the weaker at least ``min_weight`` of their sum.
"""

from __future__ import annotations

import torch

from tpnet_gpu.disparity.pairs import AxisSampler, WindowOverlap

SHAPE_STEP = 0.25  # px between the candidate positions (and the samples of the tiles' shapes)
DATA_STEP = 0.5  # px between the profile samples a tile is fitted on
ONE_SURFACE = 0.5  # px: two shapes at most this far apart model one surface's peak
SUB_CHUNK = 1024  # tiles fitted at once: bounds the (tiles, pairs, samples, candidates) basis (~25 MB)
# Settings chosen on the tuning scenes (seeds 20-22, 640x480; motion_and_surfaces.md §4)
MIN_GAIN, MIN_WEIGHT, RADIUS = 0.9, 0.15, 0.5


def cut_plan(vectors: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(partners (P, J), directions (P, J, 2))``: the pairs whose correlations give pair p's shape and the lag
    per px to read them along - the pairs perpendicular to p, along p's own lag vector; a pair with none (e.g. a
    binocular rig) reads itself across its axis (p's vector turned by 90 degrees: right for isotropic peaks).
    Rows are padded to the longest by repeating their first entry."""
    v = vectors.detach().cpu().double()
    norms = v.norm(dim=1)
    rows = []
    for p in range(len(v)):
        across = [q for q in range(len(v)) if abs(float(v[p] @ v[q])) <= 1e-6 * float(norms[p] * norms[q])]
        rows.append([(q, v[p]) for q in across] or [(p, torch.stack([-v[p, 1], v[p, 0]]))])
    width = max(len(r) for r in rows)
    rows = [r + [r[0]] * (width - len(r)) for r in rows]
    partners = torch.tensor([[q for q, _ in r] for r in rows], device=vectors.device)
    directions = torch.stack([torch.stack([d for _, d in r]) for r in rows]).to(vectors)
    return partners, directions


class LobeFit:
    """``measure(corr (T, P, 15, 15), low (T,), high (T,)) -> (two (T,) bool, w_high (T,))``: whether the tiles'
    correlations hold two surfaces near the offsets ``low`` < ``high`` px from their targets, and the share of
    the peak near ``high`` (module docstring). The profiles are read over +-``reach`` px (``low`` and ``high``
    within +-(``reach`` - 1)); ``min_separation``: closer peaks are one surface."""

    def __init__(self, sampler: AxisSampler, *, reach: float, min_separation: float, min_gain: float = MIN_GAIN,
                 min_weight: float = MIN_WEIGHT, radius: float = RADIUS):
        for name, value in (("reach", reach - 1.0), ("radius", radius)):
            if not value > 0:
                raise ValueError(f"{name}: expected a number of pixels > 0 (reach > 1), got {value!r}")
        if not min_separation > ONE_SURFACE:
            raise ValueError(f"min_separation: expected more than {ONE_SURFACE} px, got {min_separation!r}")
        if not min_gain > 0 or not 0 <= min_weight < 0.5:
            raise ValueError(f"min_gain, min_weight: expected > 0 and in [0, 0.5), got {min_gain!r}, {min_weight!r}")
        self.sampler, self.min_gain, self.min_weight, self.radius = sampler, min_gain, min_weight, radius
        device = sampler.vectors.device
        n, m = round(reach / DATA_STEP), round((reach - 1.0) / SHAPE_STEP)
        self.offsets = DATA_STEP * torch.arange(-n, n + 1, device=device, dtype=torch.float32)  # (E,) data
        self.candidates = SHAPE_STEP * torch.arange(-m, m + 1, device=device, dtype=torch.float32)  # (K,) peaks
        self.half = round((n * DATA_STEP) / SHAPE_STEP) + m  # the shapes' samples: |offset - candidate| <= half
        self.shifts = SHAPE_STEP * torch.arange(-self.half, self.half + 1, device=device, dtype=torch.float32)
        self.index = torch.round((self.offsets[:, None] - self.candidates[None, :]) / SHAPE_STEP).long() + self.half
        i, j = torch.triu_indices(len(self.candidates), len(self.candidates), 0, device=device)
        apart = self.candidates[j] - self.candidates[i]
        keep = (apart >= min_separation) | (apart <= ONE_SURFACE)
        self.i, self.j = i[keep], j[keep]  # (C,) pairs of candidates, i <= j
        self.two, self.alone = apart[keep] >= min_separation, self.i == self.j
        self.partners, self.directions = cut_plan(sampler.vectors)
        overlap = WindowOverlap(device)
        lag = -self.candidates[None, :, None] * sampler.vectors[:, None, :]  # (P, K, 2)
        # a peak at lag s keeps overlap(s) of its height (the windows overlap less): the raw profiles are fitted
        self.attenuation = overlap(lag[..., 0]) * overlap(lag[..., 1])  # (P, K)

    def shapes(self, corr: torch.Tensor, profiles: torch.Tensor) -> torch.Tensor:
        """``(T, P, N)`` each tile's single-surface shape along each pair's axis at ``self.shifts``, 1 at 0: its
        perpendicular pairs' correlations read along the pair's axis through their own axis ``profiles``'
        maxima ``(T, P, E)``, summed, made symmetric; 0 where no peak."""
        peaks = self.offsets[torch.argmax(profiles, dim=2)]  # (T, P) each pair's strongest offset
        total = 0.0
        for k in range(self.partners.shape[1]):
            partner = self.partners[:, k]  # a partner's peak at residual d lies at lag -d v
            origin = -peaks[:, partner, None] * self.sampler.vectors[partner][None]  # (T, P, 2)
            cut = self.sampler.sample(corr[:, partner], self.shifts, "bicubic", vectors=self.directions[:, k],
                                      origin=origin, normalise=False)
            total = total + torch.nan_to_num(cut, nan=0.0)
        total = 0.5 * (total + total.flip(2))
        centre = total[:, :, self.half: self.half + 1]
        return torch.where(centre > 0, total / centre.clamp(min=1e-12), torch.zeros_like(total))

    def measure(self, corr: torch.Tensor, low: torch.Tensor, high: torch.Tensor):
        parts = [self._measure(*args) for args in zip(corr.split(SUB_CHUNK), low.split(SUB_CHUNK),
                                                       high.split(SUB_CHUNK))]
        return torch.cat([p[0] for p in parts]), torch.cat([p[1] for p in parts])

    def _measure(self, corr: torch.Tensor, low: torch.Tensor, high: torch.Tensor):
        y = torch.nan_to_num(self.sampler.sample(corr, self.offsets, "bicubic", normalise=False), nan=0.0)
        shape = self.shapes(corr, y)  # y: (T, P, E) the raw profiles
        basis = shape[:, :, self.index] * self.attenuation[None, :, None, :]  # (T, P, E, K) each candidate's peak
        gram = torch.einsum("tpek,tpel->tkl", basis, basis)  # (T, K, K)
        g = torch.einsum("tpe,tpek->tk", y, basis)  # (T, K) the data against each shifted shape
        gii, gjj, gij = gram[:, self.i, self.i], gram[:, self.j, self.j], gram[:, self.i, self.j]  # (T, C)
        det = gii * gjj - gij**2
        alone = self.alone[None] | (det <= 1e-6 * gii * gjj)  # one shape (or two indistinguishable): fit alone
        det = torch.where(alone, torch.ones_like(det), det)
        gi, gj = g[:, self.i], g[:, self.j]
        ai = torch.where(alone, gi / gii.clamp(min=1e-12), (gjj * gi - gij * gj) / det)  # (T, C) amplitudes
        aj = torch.where(alone, torch.zeros_like(gj), (gii * gj - gij * gi) / det)
        gain = ai * gi + aj * gj  # the residual's reduction by each pair's least-squares fit
        nothing = torch.full_like(gain, -float("inf"))
        one = torch.where(~self.two[None], gain, nothing).amax(dim=1)
        near = ((self.candidates[self.i][None] - low[:, None]).abs() <= self.radius) & (
            (self.candidates[self.j][None] - high[:, None]).abs() <= self.radius)
        gain = torch.where(self.two[None] & near & (ai > 0) & (aj > 0), gain, nothing)
        best = torch.argmax(gain, dim=1, keepdim=True)  # (T, 1)
        total = (y**2).sum(dim=(1, 2))
        rss2 = total - gain.gather(1, best)[:, 0]  # residual of the best two-surface pair (inf where none)
        rss1 = total - one  # of the best one-surface model anywhere
        a_low, a_high = ai.gather(1, best)[:, 0], aj.gather(1, best)[:, 0]
        w_high = a_high / (a_low + a_high).clamp(min=1e-12)
        two = torch.isfinite(rss2) & (rss1 >= self.min_gain * rss2.clamp(min=1e-12)) & (
            torch.minimum(w_high, 1 - w_high) >= self.min_weight) & (shape[:, :, self.half] > 0).all(dim=1)
        return two, w_high
