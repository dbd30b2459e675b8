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

CORR_SIZE = 15  # side of a pair correlation tile, lags -7..7
CORR_CENTRE = 7
NUM_PAIRS = 6
ORTHO_PAIRS = (0, 1, 2, 3)
TRANSPOSED_PAIRS = (2, 3)  # vertical pairs: transpose so the disparity axis is +x
DIAG_PAIRS = (4, 5)
FLIPPED_PAIRS = (5,)  # diag-other: rows flipped (row -> 14 - row) onto the main diagonal
NUM_PARS = 5  # x0, Wm, Wxy, A_ortho, A_diag (Wyd is fixed at 0, lma_adjust_wy = false)
X0, WM, WXY, A_ORTHO, A_DIAG = range(NUM_PARS)
GROUP_SCALES = (1.0, np.sqrt(2.0))  # s of the model per group: ortho, diagonal
SINGULAR_RCOND = 1e-13  # reciprocal condition (unit-diagonal scaled) below which a step matrix is singular


@dataclass(frozen=True)
class LmaParams:
    """LMA defaults (C.7, the original's ImageDttParameters). Names follow C.7; units in the comments."""

    half_width: float = 2.0  # lma_half_width: initial and regularisation target of Wm [px]
    cost_wy: float = 0.1  # lma_cost_wy: weight of the residual (Wm - half_width), before normalisation
    cost_wxy: float = 0.1  # lma_cost_wxy: weight of the residual (Wxy - 0), before normalisation
    lambda_initial: float = 0.1  # lma_lambda_initial
    lambda_good: float = 0.5  # lma_lambda_scale_good: lambda factor after an accepted step
    lambda_bad: float = 8.0  # lma_lambda_scale_bad: lambda factor after a rejected step
    lambda_max: float = 100.0  # lma_lambda_max: give up when lambda exceeds it
    rms_diff: float = 0.001  # lma_rms_diff: finish when an accepted step lowers the cost by less (relative)
    num_iter: int = 20  # lma_num_iter: maximal number of LM steps
    cnvx_weight: float = 0.5  # cnvx_weight: mask weight of selected non-convex cells (and the 3x3 fill)
    vasw_pwr: float = 2.0  # ortho_vasw_pwr: sample weight ~ |value| ** vasw_pwr
    hwnd: int = 4  # cnvx_hwnd_size: half-size of the sample box [px], 9x9 for 4

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in ("num_iter", "hwnd"):
                if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < 1:
                    raise ValueError(f"LmaParams.{f.name}: expected an integer >= 1, got {value!r}")
            elif not np.isfinite(value):
                raise ValueError(f"LmaParams.{f.name}: expected a finite number, got {value!r}")
        if self.hwnd > CORR_CENTRE:
            raise ValueError(f"LmaParams.hwnd: expected <= {CORR_CENTRE}, got {self.hwnd}")
        for name in ("half_width", "lambda_initial", "lambda_good", "lambda_bad", "lambda_max"):
            if getattr(self, name) <= 0:
                raise ValueError(f"LmaParams.{name}: expected > 0, got {getattr(self, name)!r}")
        for name in ("cost_wy", "cost_wxy", "rms_diff", "cnvx_weight", "vasw_pwr"):
            if getattr(self, name) < 0:
                raise ValueError(f"LmaParams.{name}: expected >= 0, got {getattr(self, name)!r}")


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


def combine_groups(corr, pairs_mask=None):
    """Average the 6 pair correlations into the ortho and diagonal LMA groups (B.4).

    Parameters
    ----------
    corr : array_like, ``(tiles, 6, 15, 15)``
        Pair correlations in the B.1 pair order; row = y lag + 7, column = x lag + 7.
    pairs_mask : array_like of bool, ``(6,)`` or ``(tiles, 6)``, optional
        Pairs to use (default all). A pair whose 15x15 is entirely NaN counts as missing for that tile.

    Returns
    -------
    ortho, diag : ``(tiles, 15, 15)`` float64
        Ortho: mean of pairs 0, 1 as is and 2, 3 transposed (disparity axis along +x). Diagonal: mean of
        pair 4 as is and pair 5 flipped vertically (row -> 14 - row), both along the main diagonal x = y.
        NaN where a group has no pair.
    n_ortho, n_diag : ``(tiles,)`` int64
        How many pairs were averaged into each group (4 and 2 with the default mask).
    """
    corr = np.asarray(corr, dtype=np.float64)
    if corr.ndim != 4 or corr.shape[1:] != (NUM_PAIRS, CORR_SIZE, CORR_SIZE):
        raise ValueError(f"corr: expected shape (tiles, 6, 15, 15), got {corr.shape}")
    tiles = corr.shape[0]
    if pairs_mask is None:
        mask = np.ones((tiles, NUM_PAIRS), dtype=bool)
    else:
        mask = np.asarray(pairs_mask)
        if mask.dtype != bool:
            raise TypeError(f"pairs_mask: expected a bool array, got dtype {mask.dtype}")
        if mask.shape not in ((NUM_PAIRS,), (tiles, NUM_PAIRS)):
            raise ValueError(f"pairs_mask: expected shape (6,) or ({tiles}, 6), got {mask.shape}")
        mask = np.broadcast_to(mask, (tiles, NUM_PAIRS))
    present = ~np.all(np.isnan(corr), axis=(2, 3))  # (tiles, 6); an all-NaN pair is a missing pair
    use = mask & present

    def aligned(pair):
        if pair in TRANSPOSED_PAIRS:
            return np.swapaxes(corr[:, pair], -1, -2)
        if pair in FLIPPED_PAIRS:
            return corr[:, pair, ::-1, :]
        return corr[:, pair]

    def mean_of(pairs):
        total = np.zeros((tiles, CORR_SIZE, CORR_SIZE))
        for pair in pairs:
            total += np.where(use[:, pair, None, None], aligned(pair), 0.0)
        count = use[:, list(pairs)].sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            group = total / count[:, None, None]  # 0 / 0 -> NaN for an empty group
        return group, count.astype(np.int64)

    ortho, n_ortho = mean_of(ORTHO_PAIRS)
    diag, n_diag = mean_of(DIAG_PAIRS)
    return ortho, diag, n_ortho, n_diag


def _shift(a, di: int, dj: int):
    """Move the content of ``(T, N, N)`` masks by (di rows, dj columns), filling with False."""
    out = np.zeros_like(a)
    n = a.shape[-1]
    src_i = slice(max(-di, 0), n - max(di, 0))
    dst_i = slice(max(di, 0), n - max(-di, 0))
    src_j = slice(max(-dj, 0), n - max(dj, 0))
    dst_j = slice(max(dj, 0), n - max(-dj, 0))
    out[:, dst_i, dst_j] = a[:, src_i, src_j]
    return out


def _convex_mask(values, valid, hwnd: int, cnvx_weight: float):
    """Region-grown sample mask in the local box around the start cell (C.4, ``filterConvex``).

    values: ``(T, N, N)`` box of one group, N = 2 hwnd + 1, start at (hwnd, hwnd), NaN outside the tile.
    valid: ``(T, N, N)`` bool, box cell inside the 15x15 tile (the box clipped to the tile is a rectangle).
    Returns the mask weight ``(T, N, N)``: 1 for selected convex cells, ``cnvx_weight`` for selected
    non-convex cells and for the still-empty cells of the 3x3 around the start, 0 elsewhere.
    """
    n = 2 * hwnd + 1
    convex = np.zeros_like(valid)
    v = values
    inner = v[:, 1:-1, 1:-1]
    # A NaN neighbour (outside the tile = on the clipped box edge, or missing data) makes the test False,
    # so "convex" is only ever true strictly inside the clipped box, as in the spec.
    convex[:, 1:-1, 1:-1] = (2 * inner > v[:, 1:-1, :-2] + v[:, 1:-1, 2:]) & (
        2 * inner > v[:, :-2, 1:-1] + v[:, 2:, 1:-1]
    )
    convex &= valid
    di, dj = np.meshgrid(np.arange(n) - hwnd, np.arange(n) - hwnd, indexing="ij")
    sel = np.zeros_like(valid)
    sel[:, hwnd, hwnd] = valid[:, hwnd, hwnd]
    # Growth directions: (ring cells on this side, outward move, side-cell test and moves).
    sides = (
        (lambda k: (di == -k) & (np.abs(dj) <= k), (-1, 0), dj, ((0, -1), (0, 1))),  # up
        (lambda k: (di == k) & (np.abs(dj) <= k), (1, 0), dj, ((0, -1), (0, 1))),  # down
        (lambda k: (dj == -k) & (np.abs(di) <= k), (0, -1), di, ((-1, 0), (1, 0))),  # left
        (lambda k: (dj == k) & (np.abs(di) <= k), (0, 1), di, ((-1, 0), (1, 0))),  # right
    )
    for ring in range(hwnd):
        # Every ring grows from the previous selection; a ring that adds nothing leaves the next rings
        # empty too, so running all rings equals the spec's early stop.
        source = sel & (convex | (ring == 0))  # the start cell is exempt from the convexity test
        new = sel.copy()
        for ring_cells, (oi, oj), across, ((ai, aj), (bi, bj)) in sides:
            reached = _shift(source & ring_cells(ring)[None], oi, oj) & valid
            new |= reached
            conv_reached = reached & convex  # convex => all 4 neighbours lie in the clipped box
            new |= _shift(conv_reached & (across <= 0)[None], ai, aj)
            new |= _shift(conv_reached & (across >= 0)[None], bi, bj)
        sel = new
    weight = np.where(sel, np.where(convex, 1.0, cnvx_weight), 0.0)
    centre = np.zeros((n, n), dtype=bool)
    centre[hwnd - 1 : hwnd + 2, hwnd - 1 : hwnd + 2] = True
    fill = centre[None] & valid & (weight == 0.0)
    return np.where(fill, cnvx_weight, weight)


def _gather_box(group, row0, col0, hwnd: int):
    """Box ``(T, N, N)`` of ``group (T, 15, 15)`` centred at (row0, col0) ``(T,)``; NaN and invalid outside."""
    off = np.arange(-hwnd, hwnd + 1)
    rows = row0[:, None, None] + off[None, :, None]
    cols = col0[:, None, None] + off[None, None, :]
    valid = (rows >= 0) & (rows < CORR_SIZE) & (cols >= 0) & (cols < CORR_SIZE)
    t = np.arange(group.shape[0])[:, None, None]
    box = group[t, np.clip(rows, 0, CORR_SIZE - 1), np.clip(cols, 0, CORR_SIZE - 1)]
    return np.where(valid, box, np.nan), valid


def _samples(ortho, diag, ixc, n_ortho, n_diag, params: LmaParams):
    """Sample values, raw weights and coordinates ``(T, S)``, and the group of each sample ``(S,)`` (0 ortho,
    1 diagonal), S = 2 (2 hwnd + 1)^2; cells that are not samples have weight 0."""
    h = params.hwnd
    centre = ixc + CORR_CENTRE
    off = np.arange(-h, h + 1)
    di, dj = np.meshgrid(off, off, indexing="ij")
    values, weights, xs, ys, groups = [], [], [], [], []
    for group, row0, count, diagonal in (
        (ortho, np.full_like(centre, CORR_CENTRE), n_ortho, False),
        (diag, centre, n_diag, True),
    ):
        box, valid = _gather_box(group, row0, centre, h)
        mask = _convex_mask(box, valid, h, params.cnvx_weight)
        finite = np.isfinite(box)
        v = np.where(finite, box, 0.0)
        w = mask * count[:, None, None] * np.abs(v) ** params.vasw_pwr
        w = np.where(finite & (w > 0), w, 0.0)  # the spec keeps only samples with weight > 0
        if diagonal:  # rotated coordinates of pixel lag (ixc + dj, ixc + di)
            x = ixc[:, None, None] + (di + dj)[None] / 2.0
            y = np.broadcast_to((di - dj)[None] / 2.0, x.shape)
        else:
            x = ixc[:, None, None] + dj[None].astype(np.float64)
            y = np.broadcast_to(di[None].astype(np.float64), x.shape)
        tiles = v.shape[0]
        values.append(v.reshape(tiles, -1))
        weights.append(w.reshape(tiles, -1))
        xs.append(x.reshape(tiles, -1))
        ys.append(y.reshape(tiles, -1))
        groups.append(np.full(values[-1].shape[1], int(diagonal)))
    return (np.concatenate(values, 1), np.concatenate(weights, 1), np.concatenate(xs, 1),
            np.concatenate(ys, 1), np.concatenate(groups))


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
