"""Per-tile measurement of the residual disparity from pair correlations: one ``Measurer`` for any rig; and the
2-D peak of one combined correlation per tile (``Peak2D``: motion vectors, a pair's full 2-D offset).

For the quad's 6 pairs with ``EngineConfig.measure == "lma"`` it is the baseline's measurement (strips -> centre
of mass -> LMA peak fit, geometry_and_lma.md C.1-C.4; float64 NumPy, so the active tiles' correlations make a
host round trip); a rig whose pairs each lie along one of the quad's pairs (``lma_slots``: a binocular rig's
pair is the quad's pair 0) gets the same measurement with the other quad pairs masked off. Otherwise (other
rigs, or ``"axis"``) the peak of the pairs' combined correlation read along their axes (``pairs.AxisSampler``)
at quarter-pixel offsets, refined by a parabola - torch on the device. Measured on 4 rendered 640x480 tuning
scenes: flat own-inlier RMSE 0.07-0.11 px for both.
"""

from __future__ import annotations

import functools

import numpy as np
import torch
import torch.nn.functional as F

from tpnet_gpu import tables
from tpnet_gpu.baseline.estimate import BaselineParams, measure as lma_measure
from tpnet_gpu.config import EngineConfig
from tpnet_gpu.disparity.pairs import AxisSampler, WindowOverlap, combine_pairs, pair_vectors
from tpnet_gpu.layout import CORR_RADIUS

PEAK_OFFSETS = 0.25  # px between the offsets the generic peak is read at
SLOT_TOLERANCE = 0.02  # baselines: a pair's lag vector within this of a quad pair's takes that pair's LMA slot
# Tiles read per step after a pass (here and in the engine's sweeps): bounds the temporaries - at 5 MPix a
# pass's (tiles, pairs, lags) samples would be ~0.2 GB at once, a copy of the active correlations up to 0.4 GB.
CHUNK = 8192


class RowBuffer:
    """A ``(CHUNK, ...)`` buffer that ``row_chunks`` copies rows into, made on first use and remade only for rows of
    another shape, dtype or device: a copy into a fresh 44 MB chunk (5 MPix, 8192 tiles of quad correlations) is
    page-faulted in anew each time (glibc maps blocks over 32 MB per allocation), which cost ~6x the copy itself."""

    def __init__(self):
        self._buffer = None

    def rows(self, x: torch.Tensor, n: int) -> torch.Tensor:
        """``(n, *x.shape[1:])``: the first ``n`` rows of the buffer (n <= CHUNK), valid until the next call."""
        b = self._buffer
        if b is None or b.shape[1:] != x.shape[1:] or b.dtype != x.dtype or b.device != x.device:
            b = self._buffer = x.new_empty((CHUNK, *x.shape[1:]))
        return b[:n]


def row_chunks(x: torch.Tensor, index: torch.Tensor, buffer: RowBuffer | None = None):
    """``(part, rows)`` for each CHUNK of ``index`` ``(N,)``: the rows of ``x`` it names - views when ``index``
    is every row in order (a full pass: no copy of its correlations), copies otherwise (into ``buffer`` when
    given: each chunk's rows are then valid only until the next chunk)."""
    everything = index.numel() == x.shape[0]  # nonzero / arange give every row in order then
    for start, part in zip(range(0, index.numel(), CHUNK), index.split(CHUNK)):
        if everything:
            yield part, x.narrow(0, start, part.numel())
        elif buffer is None:
            yield part, x.index_select(0, part)
        else:
            yield part, torch.index_select(x, 0, part, out=buffer.rows(x, part.numel()))


WIDEN_SIGMA = 0.9  # px: Gaussian blur of mono correlations before the peak is located
RIVAL_APART = 1.5  # px: a rival peak (Peak2D.rival) is a local maximum at least this far from the measured one


@functools.lru_cache(maxsize=None)
def _blur_matrix(side: int, sigma: float, device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    """``(side, side)`` B with (B x)[i] = sum_t g[t] x[clamp(i + t - 3)]: the 7-tap Gaussian (std ``sigma``) with
    edges replicated, as one matrix (made once per size, sigma and device)."""
    taps = torch.arange(-3.0, 4.0, dtype=torch.float64)
    g = torch.exp(-(taps**2) / (2 * sigma**2))
    g = g / g.sum()
    matrix = torch.zeros(side, side, dtype=torch.float64)
    rows = torch.arange(side)
    for t in range(7):
        matrix.index_put_((rows, (rows + t - 3).clamp(0, side - 1)), g[t].expand(side), accumulate=True)
    return matrix.to(device=device, dtype=dtype)


def gaussian_blur(corr: torch.Tensor, sigma: float) -> torch.Tensor:
    """Separable Gaussian blur (std ``sigma`` px, 7 taps, edges replicated) of correlations ``(T, P, 15, 15)``:
    B corr B^T with the blur's matrix B - batched 15x15 products, ~30x faster on the CPU than two 1-channel
    convolutions of the padded tiles (53 -> 1.7 ms for 4800 tiles, 2 threads)."""
    matrix = _blur_matrix(corr.shape[-1], float(sigma), corr.device, corr.dtype)
    return matrix @ corr @ matrix.T


def lma_slots(vectors) -> tuple[int, ...] | None:
    """The quad pair (``tables.QUAD_PAIRS`` order) each pair of lag vectors ``vectors (P, 2)`` (``pair_vectors``,
    baselines) lies along, within ``SLOT_TOLERANCE``; None when a pair lies along none or two pairs take one
    slot (the LMA then does not apply). The quad's own pairs give 0..5, a binocular rig's (1, 0) gives (0,)."""
    quad = pair_vectors(tables.QUAD_OFFSETS, tables.QUAD_PAIRS)
    slots = []
    for v in torch.as_tensor(vectors, dtype=torch.float64).cpu().numpy():
        free = [s for s in range(len(quad)) if s not in slots and abs(quad[s] - v).max() <= SLOT_TOLERANCE]
        if not free:
            return None
        slots.append(free[0])
    return tuple(slots)


class Measurer:
    """``measure(corr (T, P, 15, 15), active (T,)) -> (residual (T,), strength (T,))``, NaN / 0 where none.

    ``widen``: locate peaks on Gaussian-blurred correlations (mono: the phase-correlation peak of a mono tile is
    a near-delta, about 0.4 px wide, whose sub-pixel position a parabola through interpolated samples pulls
    toward whole lags - median error 0.04 px at fractional shifts of an 8-bit photograph pair, 0.011 blurred);
    the strength is still read on the unblurred correlations, so the thresholds keep their meaning."""

    def __init__(self, pairs, sampler: AxisSampler, config: EngineConfig, widen: bool = False):
        self.widen = widen
        slots = None
        if config.measure == "lma":
            slots = tuple(range(len(pairs))) if tuple(pairs) == tables.QUAD_PAIRS else lma_slots(sampler.vectors)
        self.lma = slots is not None
        # other pairs or another order: the correlations go into these quad slots, the slots not taken masked off
        self.slots = None if slots is None or slots == tuple(range(len(tables.QUAD_PAIRS))) else list(slots)
        if self.slots is not None:
            self.present = np.zeros(len(tables.QUAD_PAIRS), dtype=bool)  # (6,) the quad slots taken
            self.present[self.slots] = True
        self.sampler = sampler
        self.params = BaselineParams(min_strength=config.min_strength, trust=config.trust, tolerance=config.tolerance)
        reach = min(sampler.reach, config.trust + 1.0)
        device = sampler.vectors.device
        self.offsets = torch.arange(-reach, reach + 1e-6, 1.0, device=device)  # whole-pixel search
        self.rows = RowBuffer()  # the active tiles' correlations, a chunk at a time (also the engine's sweeps)
        self.fine = sampler.table(self.offsets[:, None] + peak_window(device)[None, :])  # axis_peak's, per centre

    def measure(self, corr: torch.Tensor, active: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        tiles = corr.shape[0]
        residual = torch.full((tiles,), float("nan"), device=corr.device)
        strength = torch.zeros((tiles,), device=corr.device)
        for index, sub in row_chunks(corr, torch.nonzero(active, as_tuple=True)[0], self.rows):  # bounded
            if self.lma:  # the LMA runs in float64 NumPy (a host round trip of the active tiles)
                m = self._lma(sub.detach().cpu().numpy())
                d = torch.as_tensor(m.residual, dtype=torch.float32, device=corr.device)
                s = torch.as_tensor(m.strength, dtype=torch.float32, device=corr.device)
            else:
                d, s = self._peak(sub)
            residual[index], strength[index] = d, s
        return residual, strength

    def _lma(self, corr):
        """The baseline's measurement of ``corr (T, P, 15, 15)`` (NumPy), the rig's pairs in their quad slots."""
        if self.slots is None:
            return lma_measure(corr, self.params)
        full = np.zeros((corr.shape[0], len(self.present), *corr.shape[2:]), dtype=np.float64)  # (T, 6, 15, 15)
        full[:, self.slots] = corr
        return lma_measure(full, self.params, self.present)

    def _peak(self, corr: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Whole-pixel peak of the combined correlation (bilinear, cheap), then ``axis_peak`` around it."""
        raw = corr
        if self.widen:
            corr = gaussian_blur(corr, WIDEN_SIGMA)
        coarse = torch.nan_to_num(combine_pairs(self.sampler.sample(corr, self.offsets)), nan=-1.0)
        k = torch.argmax(coarse, dim=1)  # (T,) each tile's whole-pixel centre
        e, strength, ok = axis_peak(self.sampler, corr, self.offsets[k],
                                    self.sampler.sample_rows(corr, self.fine, k, "bicubic"))
        if self.widen:
            strength = combine_pairs(self.sampler.sample(raw, e[:, None].nan_to_num(0.0), "bicubic"))[:, 0]
        return e, torch.where(ok, strength, torch.zeros_like(e))


@functools.lru_cache(maxsize=None)
def peak_window(device: torch.device) -> torch.Tensor:
    """``(9,)`` offsets (px) of the fine samples around a whole-pixel peak: +-1 px in ``PEAK_OFFSETS`` steps (made
    once per device: the per-frame path allocates no constants)."""
    return PEAK_OFFSETS * torch.arange(-4, 5, device=device, dtype=torch.float32)


def axis_peak(sampler: AxisSampler, corr: torch.Tensor, centre: torch.Tensor, samples: torch.Tensor | None = None):
    """The combined correlation's peak within +-1 px of ``centre (T,)`` (px along the pairs' axes): bicubic samples
    at quarter pixels (bilinear samples of a sharp peak pull the parabola toward whole lags), the best one, and a
    parabola through it and its neighbours. Returns ``(e (T,), value (T,), ok (T,))``; e NaN where the best
    sample is at the window's end or no parabola vertex is a maximum. ``samples``: those bicubic samples
    ``(T, P, 9)`` when the caller has them (``AxisSampler.sample_rows`` of a table of whole-pixel centres)."""
    fine = centre[:, None] + peak_window(corr.device)[None, :]  # (T, 9)
    samples = sampler.sample(corr, fine, "bicubic") if samples is None else samples
    combined = torch.nan_to_num(combine_pairs(samples), nan=-1.0)
    j = torch.argmax(combined, dim=1, keepdim=True)
    n = combined.shape[1]
    c0 = torch.gather(combined, 1, j)
    cm = torch.gather(combined, 1, (j - 1).clamp(min=0))
    cp = torch.gather(combined, 1, (j + 1).clamp(max=n - 1))
    frac, vertex = parabola_step(cm, c0, cp)
    ok = ((j > 0) & (j < n - 1) & vertex)[:, 0]
    e = torch.gather(fine, 1, j)[:, 0] + PEAK_OFFSETS * frac[:, 0]
    return torch.where(ok, e, torch.full_like(e, float("nan"))), c0[:, 0], ok


def parabola_step(cm: torch.Tensor, c0: torch.Tensor, cp: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Vertex offset in (-0.5, 0.5) samples of the parabola through samples (-1, 0, +1), and where it is a maximum."""
    denom = cm - 2 * c0 + cp
    ok = denom < 0
    frac = torch.where(ok, 0.5 * (cm - cp) / torch.where(ok, denom, torch.ones_like(denom)), torch.zeros_like(denom))
    return frac.clamp(-0.5, 0.5), ok


class Peak2D:
    """``measure(corr (T, 15, 15)) -> (lag (T, 2) x, y px, strength (T,))``: the 2-D peak of one correlation per
    tile (e.g. pairs combined by ``combine_pairs``), NaN / 0 where none.

    As ``Measurer._peak`` in 2-D: the whole-lag maximum within +-``reach`` of the overlap-normalised correlation
    (a true shift's peak loses amplitude with the windows' overlap), then bicubic samples at quarter pixels over
    +-1 px around it, and a parabola through the best sample's neighbours in x and in y. ``widen``: located on
    the Gaussian-blurred correlation (mono near-delta peaks), the strength read on the unblurred one."""

    def __init__(self, device, *, reach: float = 6.0, widen: bool = False):
        self.widen = widen
        self.overlap = WindowOverlap(device)
        lags = torch.arange(-CORR_RADIUS, CORR_RADIUS + 1, device=device, dtype=torch.float32)
        ov = self.overlap(lags)
        self.inside = (lags.abs() <= reach)[:, None] & (lags.abs() <= reach)[None, :]  # (15, 15) searched lags
        self.coarse_scale = 1.0 / (ov[:, None] * ov[None, :]).clamp(min=0.05)
        self.lags = lags
        self.window = peak_window(torch.device(device))

    def _sample(self, corr: torch.Tensor, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """Overlap-normalised bicubic samples ``(T, N)`` of ``corr (T, 15, 15)`` at lags ``x, y (T, N)``."""
        grid = torch.stack([x, y], dim=-1)[:, None] / CORR_RADIUS  # (T, 1, N, 2)
        values = F.grid_sample(corr[:, None].float(), grid, mode="bicubic", padding_mode="zeros",
                               align_corners=True)[:, 0, 0]
        return values / (self.overlap(x) * self.overlap(y)).clamp(min=0.05)

    def _located(self, corr: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(raw, located, coarse)``, each ``(T, 15, 15)``: ``corr`` without NaN; where its peak is located
        (blurred when ``widen``); that overlap-normalised at whole lags, -inf outside +-``reach``."""
        raw = torch.nan_to_num(corr.float(), nan=0.0)
        located = gaussian_blur(raw[:, None], WIDEN_SIGMA)[:, 0] if self.widen else raw
        return raw, located, torch.where(self.inside, located * self.coarse_scale,
                                         torch.full_like(located, -float("inf")))

    def rival(self, corr: torch.Tensor) -> torch.Tensor:
        """``(T,)`` the strongest whole-lag local maximum of ``corr (T, 15, 15)`` within +-``reach`` and more
        than ``RIVAL_APART`` px from lag 0, over the strongest value within that distance (as located; not
        overlap-normalised: that would lift the noise of the far lags; 0 without a rival, 1 where nothing near
        lag 0 is positive): near 1 where a periodic or 1-D texture matches at another shift as well."""
        _, located, _ = self._located(corr)
        tiles = corr.shape[0]
        apart = (self.lags[:, None] ** 2 + self.lags[None, :] ** 2) > RIVAL_APART**2  # (15, 15)
        near = torch.where(apart, torch.full_like(located, -float("inf")), located).reshape(tiles, -1).max(dim=1).values
        top = F.max_pool2d(located[:, None], 3, stride=1, padding=1)[:, 0]
        peaks = (located >= top) & apart & self.inside
        best = torch.where(peaks, located, torch.zeros_like(located)).reshape(tiles, -1).max(dim=1).values.clamp(min=0)
        return torch.where(near > 0, best / torch.where(near > 0, near, torch.ones_like(near)), torch.ones_like(near))

    def measure(self, corr: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        tiles = corr.shape[0]
        raw, located, coarse = self._located(corr)
        flat = torch.argmax(coarse.reshape(tiles, -1), dim=1)
        side = 2 * CORR_RADIUS + 1
        cy, cx = self.lags[flat // side], self.lags[flat % side]  # (T,)
        n = len(self.window)
        fy = (cy[:, None] + self.window[None, :])[:, :, None].expand(-1, n, n).reshape(tiles, -1)
        fx = (cx[:, None] + self.window[None, :])[:, None, :].expand(-1, n, n).reshape(tiles, -1)
        fine = self._sample(located, fx, fy).reshape(tiles, n, n)  # (T, y, x)
        j = torch.argmax(fine.reshape(tiles, -1), dim=1)
        jy, jx = j // n, j % n
        rows = torch.arange(tiles, device=corr.device)
        inner = (jy > 0) & (jy < n - 1) & (jx > 0) & (jx < n - 1)
        jyc, jxc = jy.clamp(1, n - 2), jx.clamp(1, n - 2)
        c0 = fine[rows, jyc, jxc]
        dx, okx = parabola_step(fine[rows, jyc, jxc - 1], c0, fine[rows, jyc, jxc + 1])
        dy, oky = parabola_step(fine[rows, jyc - 1, jxc], c0, fine[rows, jyc + 1, jxc])
        x = cx + self.window[jxc] + PEAK_OFFSETS * dx
        y = cy + self.window[jyc] + PEAK_OFFSETS * dy
        ok = inner & okx & oky
        strength = self._sample(raw, x[:, None], y[:, None])[:, 0] if self.widen else c0
        lag = torch.where(ok[:, None], torch.stack([x, y], dim=-1), torch.full((tiles, 2), float("nan"),
                                                                                device=corr.device))
        return lag, torch.where(ok, strength, torch.zeros_like(strength))
