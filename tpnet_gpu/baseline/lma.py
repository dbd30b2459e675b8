"""Hand-crafted disparity baseline: pair groups and the LMA peak fit (geometry_and_lma.md B.4, C.4, C.7).

Float64 NumPy, vectorised over tiles: the sample masks are grown ring by ring and the Levenberg-Marquardt
solver runs step by step for all tiles at once, each tile with its own lambda and its own accept / reject
decision; finished tiles freeze. Only fixed-size blocks of tiles (``batch_size``) bound the memory.

Convention
----------
* Correlation tiles are ``(15, 15)``: row = vertical lag + 7, column = horizontal lag + 7 (B.2).
* Pair order (B.1): 0: cam 0->1 hor-top, 1: 2->3 hor-bottom, 2: 0->2 vert-left, 3: 1->3 vert-right,
  4: 0->3 diag-main, 5: 2->1 diag-other.
* A residual disparity delta puts the peak of every group at x = -delta along +x (ortho: lag (-delta, 0);
  diagonal: lag (-delta, -delta) in pixels), so the fitted centre x0 gives ``disparity = -x0``.
* Diagonal samples use rotated coordinates x_r = (cx + cy) / 2, y_r = (cy - cx) / 2 (disparity units) and the
  model scale s = sqrt(2), so the fitted widths are in pixels for both groups.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from tpnet_gpu.baseline.lma_samples import (  # noqa: F401 - LmaParams, combine_groups re-exported
    A_DIAG, A_ORTHO, CORR_SIZE, GROUP_SCALES, NUM_PARS, SINGULAR_RCOND, WM, WXY, X0, LmaParams, _samples,
    combine_groups, peak_variance, widen,
)


@dataclass(frozen=True)
class LmaResult:
    """Per-tile LMA output, all arrays ``(tiles,)``.

    disparity: residual disparity delta_hat = -x0 [px], NaN where the fit failed or the tile had no data.
    strength: sum_g gamma_g A_g (capped by the maximal sample value, C.4), 0 where rejected.
    width_m, width_xy: fitted Wm and Wxy [px] (diagnostics), NaN where rejected.
    success: bool, the spec's success rule (final cost below the initial cost).
    iterations: int, LM steps taken (accepted and rejected); 0 for tiles without data.
    """

    disparity: np.ndarray
    strength: np.ndarray
    width_m: np.ndarray
    width_xy: np.ndarray
    success: np.ndarray
    iterations: np.ndarray


def _model(p, x, y, group_of, with_jacobian: bool):
    """Paraboloid model f ``(T, K)`` and optionally its Jacobian ``(T, K, 5)`` (C.4).

    p: ``(T, 5)`` parameters; x, y: ``(T, K)`` sample coordinates; group_of: ``(T, K)`` 0 ortho / 1 diagonal.
    """
    x0, wm, wxy = p[:, X0, None], p[:, WM, None], p[:, WXY, None]
    diagonal = group_of == 1
    s = np.where(diagonal, GROUP_SCALES[1], GROUP_SCALES[0])
    amp = np.where(diagonal, p[:, A_DIAG, None], p[:, A_ORTHO, None])
    wy = wm  # Wy = Wm * scale + Wyd with scale 1 (quad) and Wyd fixed 0
    wx = wy + wxy
    dxw = s * (x - x0) / wx
    dyw = s * y / wy
    bracket = 1.0 - dxw**2 - dyw**2
    f = amp * bracket
    if not with_jacobian:
        return f, None
    dfdwx = 2.0 * amp * dxw**2 / wx
    dfdwy = 2.0 * amp * dyw**2 / wy
    jac = np.stack(
        [
            2.0 * amp * s * dxw / wx,  # d/dx0
            dfdwx + dfdwy,  # d/dWm (scale 1)
            dfdwx,  # d/dWxy
            np.where(diagonal, 0.0, bracket),  # d/dA_ortho
            np.where(diagonal, bracket, 0.0),  # d/dA_diag
        ],
        axis=-1,
    )
    return f, jac


def _cost(p, values, w, reg_w, x, y, group_of, half_width):
    """Weighted cost sqrt(sum w (y - f)^2) incl. the two regularisation residuals, ``(T,)``."""
    f, _ = _model(p, x, y, group_of, False)
    c2 = np.sum(w * (values - f) ** 2, axis=1)
    c2 = c2 + reg_w[:, 0] * (half_width - p[:, WM]) ** 2 + reg_w[:, 1] * p[:, WXY] ** 2
    return np.sqrt(c2)


def _fit_block(ortho, diag, x_start, n_ortho, n_diag, params: LmaParams):
    tiles = ortho.shape[0]
    start_ok = np.isfinite(x_start)
    ixc = np.floor(np.clip(np.where(start_ok, x_start, 0.0), -64, 64) + 0.5).astype(np.int64)  # Java round
    if params.peak_sigma_min > 0:  # widen peaks narrower than the model can follow (C.4 "Peak widening")
        variance = peak_variance(ortho, diag, ixc, params)
        narrow = start_ok & (variance > 0)
        if narrow.any():
            ortho, diag = ortho.copy(), diag.copy()
            ortho[narrow] = widen(ortho[narrow], variance[narrow])
            diag[narrow] = widen(diag[narrow], variance[narrow])
    values, raw_w, x, y, group_of = _samples(ortho, diag, ixc, n_ortho, n_diag, params)
    group_of = np.broadcast_to(group_of, raw_w.shape)
    group_sum = np.stack([np.sum(raw_w * (group_of == g), axis=1) for g in (0, 1)], axis=1)  # (T, 2)
    # Keep only the used samples (weight > 0), packed to the front and padded with weight-0 entries.
    used = raw_w > 0
    keep = max(int(used.sum(axis=1).max(initial=0)), 1)
    order = np.argsort(~used, axis=1, kind="stable")[:, :keep]
    values, raw_w, x, y, group_of = (np.take_along_axis(a, order, axis=1) for a in (values, raw_w, x, y, group_of))
    pure = group_sum.sum(1)
    ok = start_ok & (pure > 0)

    total = pure + params.cost_wy + params.cost_wxy
    total = np.where(total > 0, total, 1.0)
    w = raw_w / total[:, None]
    reg_w = np.stack([np.full(tiles, params.cost_wy), np.full(tiles, params.cost_wxy)], 1) / total[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        gamma = np.where(pure[:, None] > 0, group_sum / pure[:, None], 0.0)
    sampled = raw_w > 0
    max_value = np.max(np.where(sampled, values, -np.inf), axis=1)
    max_value = np.where(np.isfinite(max_value), max_value, 0.0)
    active_par = np.ones((tiles, NUM_PARS), dtype=bool)
    active_par[:, A_ORTHO:] = group_sum > 0  # a group without samples has no amplitude to fit

    p = np.zeros((tiles, NUM_PARS))
    p[:, X0] = np.where(ok, x_start, 0.0)
    p[:, WM] = params.half_width
    p[:, A_ORTHO:] = max_value[:, None]
    lam = np.full(tiles, params.lambda_initial)
    with np.errstate(all="ignore"):
        cost = _cost(p, values, w, reg_w, x, y, group_of, params.half_width)
    initial_cost = cost.copy()
    done = ~ok
    iterations = np.zeros(tiles, dtype=np.int64)
    eye = np.eye(NUM_PARS, dtype=bool)

    for _ in range(params.num_iter):
        idx = np.nonzero(~done)[0]
        if idx.size == 0:
            break
        pa, va, wa, xa, ya, ga = p[idx], values[idx], w[idx], x[idx], y[idx], active_par[idx]
        gra = group_of[idx]
        with np.errstate(all="ignore"):
            f, jac = _model(pa, xa, ya, gra, True)
            jw = jac * wa[:, :, None]
            hess = np.swapaxes(jw, 1, 2) @ jac  # (t, 5, 5)
            grad = np.einsum("tsp,ts->tp", jw, va - f)
            rw = reg_w[idx]
            hess[:, WM, WM] += rw[:, 0]
            hess[:, WXY, WXY] += rw[:, 1]
            grad[:, WM] += rw[:, 0] * (params.half_width - pa[:, WM])
            grad[:, WXY] += rw[:, 1] * (0.0 - pa[:, WXY])
            hess = hess + lam[idx, None, None] * hess * eye  # (J^T W J + lambda diag(J^T W J))
            # Frozen parameters (empty groups) get an identity row/column and a zero gradient.
            both = ga[:, :, None] & ga[:, None, :]
            hess = np.where(both, hess, 0.0) + np.where(eye & ~ga[:, :, None], 1.0, 0.0)
            grad = np.where(ga, grad, 0.0)
            d = np.diagonal(hess, axis1=1, axis2=2)
            good_diag = np.all(np.isfinite(hess), axis=(1, 2)) & np.all(d > 0, axis=1)
            scale = 1.0 / np.sqrt(np.where(good_diag[:, None], d, 1.0))
            scaled = np.where(good_diag[:, None, None], hess * scale[:, :, None] * scale[:, None, :], np.eye(NUM_PARS))
            eig = np.linalg.eigvalsh(scaled)
            regular = good_diag & (eig[:, 0] > SINGULAR_RCOND * eig[:, -1]) & np.all(np.isfinite(grad), axis=1)
            delta = np.linalg.solve(np.where(regular[:, None, None], scaled, np.eye(NUM_PARS)),
                                    np.where(regular[:, None], grad * scale, 0.0)[:, :, None])[:, :, 0] * scale
            p_new = pa + delta
            cost_new = _cost(p_new, va, wa, reg_w[idx], xa, ya, gra, params.half_width)
        iterations[idx] += 1
        improved = regular & (cost_new < cost[idx])  # NaN costs compare False: rejected
        finished = improved & (cost_new >= cost[idx] * (1.0 - params.rms_diff))
        lam_new = np.where(improved, lam[idx] * params.lambda_good, lam[idx] * params.lambda_bad)
        gave_up = ~regular | (~improved & (lam_new > params.lambda_max))
        acc = idx[improved]
        p[acc] = p_new[improved]
        cost[acc] = cost_new[improved]
        lam[idx] = lam_new
        done[idx[finished | gave_up]] = True

    # Success rule: finished on an accepted step or ended below the initial cost; an accepted step always
    # lowers the cost, so both reduce to cost < initial cost. A start that already fits exactly also counts.
    success = ok & ((cost < initial_cost) | (initial_cost == 0.0))
    strength = np.sum(gamma * p[:, A_ORTHO:], axis=1)
    strength = np.where(strength > 1.25 * np.maximum(max_value, 0.0), np.maximum(max_value, 0.0), strength)
    nan = np.full(tiles, np.nan)
    return LmaResult(
        disparity=np.where(success, -p[:, X0], nan),
        strength=np.where(success, strength, 0.0),
        width_m=np.where(success, p[:, WM], nan),
        width_xy=np.where(success, p[:, WXY], nan),
        success=success,
        iterations=np.where(ok, iterations, 0),
    )


def _counts(n, tiles: int, name: str):
    n = np.asarray(n)
    if n.ndim == 0:
        n = np.full(tiles, n)
    if n.shape != (tiles,):
        raise ValueError(f"{name}: expected a scalar or shape ({tiles},), got {n.shape}")
    if not np.all(np.isfinite(n)) or np.any(n < 0):
        raise ValueError(f"{name}: expected finite counts >= 0, got min {np.min(n) if n.size else None}")
    return n.astype(np.float64)


def fit_peaks(ortho, diag, x_start, *, n_ortho=4, n_diag=2, params: LmaParams = LmaParams(),
              batch_size: int = 8192) -> LmaResult:
    """Fit the shared paraboloid peak to the ortho and diagonal groups of each tile (C.4).

    Parameters
    ----------
    ortho, diag : array_like, ``(tiles, 15, 15)``
        Group correlations from :func:`combine_groups` (disparity axis +x, resp. the main diagonal).
    x_start : array_like, ``(tiles,)``
        Start x0 = centre-of-mass x_cm in lag units along +x (the peak of a residual delta is at -delta).
    n_ortho, n_diag : int or array_like ``(tiles,)``
        Pairs averaged per group (sample weight factor); a group with 0 pairs contributes no samples.
    params : LmaParams
        Solver and sampling settings (C.7 defaults).
    batch_size : int
        Tiles processed together (memory ~ 15 kB per tile); results do not depend on it.

    Returns
    -------
    LmaResult
        ``(tiles,)`` arrays. Tiles with all-zero or all-NaN samples, or a NaN x_start, get disparity NaN,
        strength 0 and success False; failed fits likewise.

    Notes
    -----
    The start cell is ixc = floor(x_start + 0.5) (Java ``Math.round``, halves round up); boxes reaching past
    the 15x15 tile are clipped as in ``filterConvex``. As in C.4: no range check on the fitted x0 (the caller
    applies the trust range, C.6) and no sign check on the strength (negative correlations give a negative
    strength; the caller's min-strength gates apply).
    Deviations: NaN / infinite cells are dropped from the samples and from the group weights gamma (the Java
    sums NaN weights into gamma); a tile whose start already fits exactly (cost 0) counts as a success; a
    step matrix is singular when its unit-diagonal scaled reciprocal condition is below 1e-13 (Jama only
    fails on exact singularity), which ends that tile's fit like the spec's singular matrix.
    Addition (C.4 "Peak widening", issue 13): a tile whose peak measures a Gaussian-equivalent sigma below
    ``params.peak_sigma_min`` has both groups low-passed to ``params.peak_sigma`` before sampling, and its
    samples, fit and strength come from the widened groups (the paraboloid pulls narrower peaks, e.g. mono
    phase correlations, to whole lags); other tiles are fitted as without it, and
    ``LmaParams(peak_sigma_min=0)`` is the original fit.
    """
    if not isinstance(params, LmaParams):
        raise TypeError(f"params: expected LmaParams, got {type(params).__name__}")
    ortho = np.asarray(ortho, dtype=np.float64)
    diag = np.asarray(diag, dtype=np.float64)
    x_start = np.asarray(x_start, dtype=np.float64)
    if ortho.ndim != 3 or ortho.shape[1:] != (CORR_SIZE, CORR_SIZE):
        raise ValueError(f"ortho: expected shape (tiles, 15, 15), got {ortho.shape}")
    if diag.shape != ortho.shape:
        raise ValueError(f"diag: expected the shape of ortho {ortho.shape}, got {diag.shape}")
    tiles = ortho.shape[0]
    if x_start.shape != (tiles,):
        raise ValueError(f"x_start: expected shape ({tiles},), got {x_start.shape}")
    if not isinstance(batch_size, (int, np.integer)) or batch_size < 1:
        raise ValueError(f"batch_size: expected an integer >= 1, got {batch_size!r}")
    n_o = _counts(n_ortho, tiles, "n_ortho")
    n_d = _counts(n_diag, tiles, "n_diag")
    # Non-finite correlation values are missing samples.
    with np.errstate(invalid="ignore"):
        ortho = np.where(np.isfinite(ortho), ortho, np.nan)
        diag = np.where(np.isfinite(diag), diag, np.nan)
    parts = [
        _fit_block(ortho[b : b + batch_size], diag[b : b + batch_size], x_start[b : b + batch_size],
                   n_o[b : b + batch_size], n_d[b : b + batch_size], params)
        for b in range(0, tiles, batch_size)
    ]
    if not parts:
        empty = np.zeros(0)
        return LmaResult(empty, empty, empty, empty, np.zeros(0, dtype=bool), np.zeros(0, dtype=np.int64))
    return LmaResult(*(np.concatenate([getattr(r, f.name) for r in parts]) for f in fields(LmaResult)))
