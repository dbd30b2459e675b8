"""Issue 16's fuzz cases over ``TileProcessor`` and their oracles, shared by the CI slice
(tests/fuzz/test_tile_processor_fuzz.py, whose docstring lists what is drawn and checked) and the campaign
(``tpnet bench fuzz``). Needs hypothesis (the ``test`` extra)."""

import numpy as np
from hypothesis import strategies as st

from tpnet_gpu import tables
from tpnet_gpu.layout import PIXEL_LIMIT
from tpnet_gpu.processor import TileProcessor

SIZES = [(16, 16), (16, 24), (24, 16), (32, 48), (40, 40)]
MAGNITUDES = [0.0, 1e-30, 1.0, 4095.0, 65535.0, 1e11, 2.0**49, 2.0**51, 1e19]
WELL_CONDITIONED = 65535.0  # textured frames up to this level: the backends agree (tile_processor.md §6.7)
AGREEMENT = 1e-3  # of the peak

_processors = {}


def _processor(backend, height, width, cfa):
    key = (backend, height, width, cfa)
    if key not in _processors:
        _processors[key] = TileProcessor(height, width, cfa=cfa, device="cpu", backend=backend)
    return _processors[key]


@st.composite
def cases(draw, sizes=SIZES):
    """One drawn ``TileProcessor`` case (a dict; module docstring of tests/fuzz/test_tile_processor_fuzz.py)."""
    height, width = draw(st.sampled_from(sizes))
    cfa = draw(st.sampled_from([None, "GRBG"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    magnitude = draw(st.sampled_from(MAGNITUDES))
    textured = draw(st.booleans())
    base = rng.uniform(0, 1, (4, height, width)) if textured else np.full((4, height, width), 0.75)
    frames = base * magnitude
    dtype = draw(st.sampled_from([np.float32, np.float64, np.uint16, np.int32]))
    if np.issubdtype(dtype, np.integer):
        frames = np.clip(np.round(frames), 0, np.iinfo(dtype).max)
    frames = frames.astype(dtype)
    bad_pixels = draw(st.integers(0, 3)) if dtype in (np.float32, np.float64) else 0
    for _ in range(bad_pixels):  # mostly where interior tiles' windows read
        frames[rng.integers(4), rng.integers(4, height - 4), rng.integers(4, width - 4)] = draw(
            st.sampled_from([np.nan, np.inf, -np.inf, 2.0 * PIXEL_LIMIT]))
    tiles = (height // 8, width // 8)
    special = st.sampled_from([0.0, 1.5, -3.25, 40.0, 1e9, np.nan, np.inf])
    if draw(st.booleans()):
        disparity = draw(special)
    else:
        disparity = rng.uniform(-6, 6, tiles).astype(np.float32)
        for _ in range(draw(st.integers(0, 2))):
            disparity[rng.integers(tiles[0]), rng.integers(tiles[1])] = draw(special)
    active = rng.uniform(size=tiles) < 0.7 if draw(st.booleans()) else None
    kernels = None
    if draw(st.booleans()):
        rows, cols = draw(st.integers(1, 3)), draw(st.integers(1, 3))
        colours = 1 if cfa is None else 3
        kernels = rng.normal(0, 0.1, (4, rows, cols, colours, 4, 8, 8)).astype(np.float32)
        kernels[..., 0, 0, 0] += 1.0  # about the identity
    return dict(height=height, width=width, cfa=cfa, frames=frames, disparity=disparity, active=active,
                kernels=kernels, textured=textured, magnitude=magnitude)


def _windows(case, centres):
    """Per tile: (active with finite centres, every window inside the image and none of them featureless - all
    pixels equal, unusable ones read as 0 -, an inside window holds a pixel that is not finite or beyond
    PIXEL_LIMIT), from the frames, the mask and the centres ``(tiles, cams, 2)``."""
    frames = case["frames"].astype(np.float64)
    height, width = case["height"], case["width"]
    tiles = centres.shape[0]
    active = np.ones(tiles, bool) if case["active"] is None else case["active"].reshape(-1)
    usable, inside, bad = np.zeros(tiles, bool), np.ones(tiles, bool), np.zeros(tiles, bool)
    flat = np.zeros(tiles, bool)
    for t in range(tiles):
        usable[t] = active[t] and np.isfinite(centres[t]).all()
        if not usable[t]:
            continue
        for cam in range(4):
            # window corner: round(centre - 8), as the kernels (float32 centres)
            x0, y0 = (int(np.floor(float(v) - 8 + 0.5)) for v in centres[t, cam])
            if x0 < 0 or y0 < 0 or x0 + 16 > width or y0 + 16 > height:
                inside[t] = False
                continue
            window = frames[cam, y0:y0 + 16, x0:x0 + 16]
            ok = np.abs(window) <= PIXEL_LIMIT
            bad[t] |= not ok.all()
            flat[t] |= np.all(np.where(ok, window, 0.0) == (window[0, 0] if ok[0, 0] else 0.0))
    return usable, inside & ~flat, bad


def _expected_valid(case, centres):
    """tile_processor.md §1.4: active, centres finite, windows inside the image, featured, their pixels usable."""
    usable, inside, bad = _windows(case, centres)
    return usable & inside & ~bad


def _surely_not_finite(case, centres):
    """Tiles that are not finite whatever the clamped reads of off-image windows hold: zero correlations."""
    usable, _, bad = _windows(case, centres)
    return ~usable | bad


def _ideal_centres(case):
    ty, tx = case["height"] // 8, case["width"] // 8
    d = np.broadcast_to(np.asarray(case["disparity"], np.float64), (ty, tx)).reshape(-1)
    gy, gx = np.mgrid[0:ty, 0:tx]
    centre = np.stack([gx.reshape(-1) * 8 + 4, gy.reshape(-1) * 8 + 4], axis=-1).astype(np.float64)
    offsets = np.asarray(tables.QUAD_OFFSETS, np.float64)
    with np.errstate(invalid="ignore"):
        return centre[:, None, :] - d[:, None, None] * offsets[None]


BACKENDS = ("warp", "taichi")


def check(case) -> dict:
    """Run ``case`` on both backends against the oracles; returns ``tiles`` (tile tasks per backend), ``valid``
    (valid tiles, Warp) and ``failures``: the names of the oracles that failed (empty when all held)."""
    failures, results = [], {}
    for backend in BACKENDS:
        if case["kernels"] is None:
            tp = _processor(backend, case["height"], case["width"], case["cfa"])
        else:
            tp = TileProcessor(case["height"], case["width"], cfa=case["cfa"], kernels=case["kernels"],
                               device="cpu", backend=backend)
        try:
            out = tp.process(case["frames"], case["disparity"], active=case["active"])
        except Exception as exc:  # noqa: BLE001 - every drawn input is of a documented form: any raise fails
            failures.append(f"{backend}: raised {type(exc).__name__}")
            continue
        results[backend] = {k: getattr(out, k).numpy().copy() for k in ("corr", "valid", "centres")}
    for backend, r in results.items():
        centres, want_centres = r["centres"], _ideal_centres(case)
        both = np.isfinite(want_centres) & (np.abs(want_centres) < 1e5)
        if not np.allclose(centres[both], want_centres[both], rtol=1e-6, atol=1e-3):
            failures.append(f"{backend}: centres")
        if not np.array_equal(r["valid"], _expected_valid(case, centres)):
            failures.append(f"{backend}: valid")
        if not np.isfinite(r["corr"]).all():
            failures.append(f"{backend}: non-finite correlations")
        if not np.all(r["corr"][_surely_not_finite(case, centres)] == 0):
            failures.append(f"{backend}: non-zero masked correlations")
    if len(results) == len(BACKENDS):
        if not np.array_equal(results["warp"]["valid"], results["taichi"]["valid"]):
            failures.append("backends: valid differs")
        elif case["textured"] and 0 < case["magnitude"] <= WELL_CONDITIONED:
            valid = results["warp"]["valid"]
            w, t = results["warp"]["corr"][valid], results["taichi"]["corr"][valid]
            if w.size and np.abs(w - t).max() > AGREEMENT * max(np.abs(w).max(), 1e-30):
                failures.append("backends: correlations differ")
    tiles = (case["height"] // 8) * (case["width"] // 8)
    valid = int(results["warp"]["valid"].sum()) if "warp" in results else 0
    return {"tiles": tiles, "valid": valid, "failures": failures}
