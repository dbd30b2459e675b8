"""Hand-crafted disparity baseline, whole frames (geometry_and_lma.md C.1, C.6): per-tile measurement from
the pair correlations (strips -> centre of mass -> LMA peak fit), initial targets from a coarse sweep, and
iterative re-correlation at the refined target. Vectorised over tiles (NumPy); the tile processor is reused.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from tpnet_gpu.baseline.lma import LmaParams, combine_groups, fit_peaks
from tpnet_gpu.baseline.strips import StripParams, centre_of_mass, combine_strips, pair_strips
from tpnet_gpu.config import BASELINE_CORRELATION  # noqa: F401 - re-exported: defaults live in config

# process(target (tiles_y, tiles_x) float32) -> pair correlations (tiles, 6, 15, 15) as NumPy
Correlator = Callable[[np.ndarray], np.ndarray]



@dataclass(frozen=True)
class BaselineParams:
    """C.6/C.7 defaults. ``magic_scale`` g: next target = T + delta / g (1.0 recommended for the LMA, the
    original used 0.85); ``trust``: largest residual (px) a measurement is believed; ``sweep``: initial
    targets tried per tile (px)."""

    strips: StripParams = StripParams()
    lma: LmaParams = LmaParams()
    use_lma: bool = True
    passes: int = 5
    tolerance: float = 0.03
    min_strength: float = 0.1
    magic_scale: float = 1.0
    trust: float = 4.0
    sweep: tuple = (0.0, 6.0, 12.0, 18.0, 24.0, 30.0, 36.0, 42.0)


@dataclass(frozen=True)
class Measurement:
    """Per tile ``(T,)``: residual disparity (NaN where rejected), strength (0 where rejected), and whether
    the LMA (rather than the centre of mass) produced it."""

    residual: np.ndarray
    strength: np.ndarray
    by_lma: np.ndarray


def measure(corr: np.ndarray, params: BaselineParams = BaselineParams(), pairs=None) -> Measurement:
    """C.1 on every tile of ``corr (T, 6, 15, 15)``: integer maximum, centre of mass, then the LMA fit where
    the peak is strong enough; the LMA result replaces the CM one where it succeeds. ``pairs``: optional bool
    mask ``(6,)`` of the quad pairs present (a rig with fewer pairs, e.g. a binocular one as pair 0); the
    others are left out of the strips' combination and of the LMA groups."""
    corr = np.nan_to_num(np.asarray(corr, dtype=np.float64))
    com = centre_of_mass(combine_strips(pair_strips(corr), params.strips.corr_offset, pairs), params.strips)
    residual = com.disparity.copy()
    strength = com.strength.copy()
    by_lma = np.zeros(len(corr), dtype=bool)
    if params.use_lma:
        ortho, diag, n_ortho, n_diag = combine_groups(corr, pairs)
        start = np.where(np.isfinite(com.x_cm) & (com.strength > params.strips.min_poly_strength), com.x_cm, np.nan)
        fit = fit_peaks(ortho, diag, start, n_ortho=n_ortho, n_diag=n_diag, params=params.lma)
        by_lma = fit.success & np.isfinite(fit.disparity) & np.isfinite(start)
        residual = np.where(by_lma, fit.disparity, residual)
        strength = np.where(by_lma, fit.strength, strength)
    return Measurement(residual, strength, by_lma)


@dataclass
class Estimate:
    """Disparity map ``(tiles_y, tiles_x)`` (NaN where no tile measurement was trusted), its strength, the
    passes each tile took, and the per-pass history of targets and residuals (for benches)."""

    disparity: np.ndarray
    strength: np.ndarray
    passes: np.ndarray
    history: list = field(default_factory=list)


def initial_targets(correlate: Correlator, shape: tuple[int, int], params: BaselineParams = BaselineParams()):
    """Coarse sweep (C.6, recommended): measure at every sweep value; per tile keep the trusted measurement
    (|delta| <= trust) with the highest strength. Returns (target, strength), NaN / 0 where none."""
    best_target = np.full(shape, np.nan)
    best_strength = np.zeros(shape)
    for value in params.sweep:
        m = measure(correlate(np.full(shape, value, dtype=np.float32)), params)
        residual = m.residual.reshape(shape)
        strength = m.strength.reshape(shape)
        better = np.isfinite(residual) & (np.abs(residual) <= params.trust) & (strength > best_strength)
        best_target = np.where(better, value + residual / params.magic_scale, best_target)
        best_strength = np.where(better, strength, best_strength)
    return best_target, best_strength


def refine(correlate: Correlator, target: np.ndarray, params: BaselineParams = BaselineParams()) -> Estimate:
    """Iterative re-correlation (C.6): re-measure at T + delta / g until |delta| or the target step is below
    ``tolerance``, or ``passes``; a sign flip of delta takes the secant zero. Tiles stop (keeping their last
    result) on a NaN or weak measurement. NaN targets are not measured (their disparity stays NaN)."""
    shape = target.shape
    t = np.asarray(target, dtype=np.float64).copy()
    active = np.isfinite(t)
    disparity = np.full(shape, np.nan)
    strength = np.zeros(shape)
    passes = np.zeros(shape, dtype=int)
    prev_t = np.full(shape, np.nan)
    prev_d = np.full(shape, np.nan)
    history = []
    for n in range(params.passes):
        if not active.any():
            break
        m = measure(correlate(np.where(np.isfinite(t), t, 0.0).astype(np.float32)), params)
        d = m.residual.reshape(shape)
        s = m.strength.reshape(shape)
        history.append({"target": t.copy(), "residual": d.copy(), "strength": s.copy()})
        good = active & np.isfinite(d) & (s >= params.min_strength) & (np.abs(d) <= params.trust)
        disparity = np.where(good, t + d / params.magic_scale, disparity)
        strength = np.where(good, s, strength)
        passes = np.where(active, n + 1, passes)
        flipped = good & np.isfinite(prev_d) & (np.sign(d) != np.sign(prev_d)) & (prev_d != d)
        with np.errstate(invalid="ignore", divide="ignore"):
            secant = (t * prev_d - prev_t * d) / (prev_d - d)
        nxt = np.where(flipped, secant, t + d / params.magic_scale)
        done = ~good | (np.abs(d) < params.tolerance) | (np.abs(nxt - t) < params.tolerance)
        prev_t, prev_d = np.where(good, t, prev_t), np.where(good, d, prev_d)
        t = np.where(good & ~done, nxt, t)
        active = active & good & ~done
    return Estimate(disparity, strength, passes, history)


def neighbour_median(values: np.ndarray) -> np.ndarray:
    """Median of the finite values among each tile's 8 neighbours, ``(ty, tx)`` (NaN where none)."""
    padded = np.pad(values, 1, constant_values=np.nan)
    windows = np.lib.stride_tricks.sliding_window_view(padded, (3, 3)).reshape(values.shape + (9,))
    ring = np.delete(windows, 4, axis=-1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rings give NaN, as documented
        return np.nanmedian(ring, axis=-1)


def consistency_pass(correlate: Correlator, first: Estimate, params: BaselineParams = BaselineParams()) -> Estimate:
    """Re-measure the tiles that disagree with their neighbours by more than 1 px (or were not measured),
    starting from the neighbours' median; keep the new result where it is stronger. This stands in for the
    original pipeline's tile growing and filtering (geometry_and_lma.md G.3): per-tile sweeps lock onto wrong
    periods of repetitive textures, which the neighbourhood usually resolves."""
    median = neighbour_median(first.disparity)
    suspect = np.isfinite(median) & ~(np.abs(first.disparity - median) <= 1.0)
    if not suspect.any():
        return first
    second = refine(correlate, np.where(suspect, median, np.nan), params)
    better = suspect & np.isfinite(second.disparity) & ~(second.strength <= first.strength)
    return Estimate(np.where(better, second.disparity, first.disparity),
                    np.where(better, second.strength, first.strength),
                    first.passes + np.where(suspect, second.passes, 0), first.history + second.history)


def estimate(correlate: Correlator, shape: tuple[int, int], params: BaselineParams = BaselineParams()) -> Estimate:
    """The whole baseline: sweep for initial targets, refine, then one neighbourhood-consistency pass."""
    target, _ = initial_targets(correlate, shape, params)
    return consistency_pass(correlate, refine(correlate, target, params), params)


def processor_correlator(processor, frames, rig=None) -> Correlator:
    """A ``Correlator`` running ``processor`` (a ``TileProcessor``) on ``frames``: ideal-rig targets go in as
    disparities; with a calibrated ``rig`` (``tpnet_gpu.camera.Rig``) its tile centres are used. The frames are
    loaded once (and again only if the processor loaded other frames in between)."""
    loaded = -1

    def correlate(target: np.ndarray) -> np.ndarray:
        nonlocal loaded
        if processor.frame_count != loaded:
            processor.load(frames)
            loaded = processor.frame_count
        if rig is None:
            out = processor.measure(target)
        else:
            out = processor.measure(centres=rig.tile_centres(target).astype(np.float32))
        return out.corr.detach().cpu().numpy()

    return correlate
