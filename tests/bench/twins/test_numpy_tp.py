"""The benchmark's NumPy peer (tpnet_gpu.bench.twins.numpy_tp, bench/twins/numpy_tp.py) against the golden float64
reference.

Oracle: tpnet_gpu.reference (bayer_planes + convert_tiles per camera, correlate per pair).
Tolerance: max |numpy - reference| <= 1e-4 x max |reference| (the peer is float32 throughout).
"""

import ast
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from tpnet_gpu import reference as ref
from tpnet_gpu import tables
from tpnet_gpu.bench.twins import common as twins_common
from tpnet_gpu.bench.twins import numpy_tp

H, W, CAMS = 48, 64, 4
TOL = 1e-4


def relative_error(got, want) -> float:
    return float(np.abs(np.asarray(got, dtype=np.float64) - want).max() / np.abs(want).max())


def random_case(seed: int, *, inside: bool = False):
    """Frames (4, 48, 64) in 0..1000 and 40 tiles of per-camera centres, multiples of 1/256 px (so float32 and
    float64 split them into corner and residual identically).

    Default: centres anywhere within 20 px of the image, four tiles wholly off it (near and far) and four on the
    round-half boundary of the window corner (p + 0.5 an integer). ``inside``: windows (almost) inside the image.
    Correlations of windows read mostly from the pair clamp have near-zero spectrum entries whose phase
    normalisation amplifies float32 rounding of the CLT, so the float32-vs-float64 correlation checks of the whole
    chain, or without a fat zero, use ``inside`` windows.
    """
    rng = np.random.default_rng(seed)
    frames = rng.uniform(0, 1000, size=(CAMS, H, W)).astype(np.float32)
    margin = 9 if inside else -20
    centres = np.stack(
        [rng.uniform(margin, W - margin, size=(40, CAMS)), rng.uniform(margin, H - margin, size=(40, CAMS))], axis=-1
    )
    if not inside:
        centres[:4] = [[-500.3, 7.0], [W + 333.7, H + 1.2], [3.1, -77.9], [W / 2, H + 1000.6]]  # wholly off
    centres[4:8] = [[8.5, 12.0], [20.5, 30.5], [13.5, 9.5], [W - 9.5, H - 11.5]]  # p + 0.5 exactly an integer
    centres = np.round(centres * 256) / 256
    return frames, centres.astype(np.float32)


def reference_clt(frames, centres, cfa):
    out = []
    for cam in range(frames.shape[0]):
        planes = frames[cam][None].astype(np.float64) if cfa is None else ref.bayer_planes(frames[cam], cfa)
        out.append(ref.convert_tiles(planes, centres[:, cam].astype(np.float64))[0])
    return np.stack(out, axis=1)  # (tiles, cams, colours, 4, 8, 8)


@pytest.mark.parametrize("cfa", ["GRBG", "RGGB", None])
def test_convert_equals_reference(cfa):
    frames, centres = random_case(1)
    got = numpy_tp.numpy_convert(frames, centres, cfa)
    want = reference_clt(frames, centres, cfa)
    assert got.dtype == np.float32
    assert got.shape == (40, CAMS, 1 if cfa is None else 3, 4, 8, 8)
    assert relative_error(got, want) <= TOL


# (cfa, pairs, inside, correlation parameters): the correlate-stage cases of both twins' tests.
CORRELATE_CASES = [
    ("GRBG", tables.QUAD_PAIRS, False, dict(colour_weights=(0.25, 0.25, 0.5), fat_zero=30.0, sigma_rb=0.5,
                                            sigma_corr=0.9)),
    ("GRBG", [(1, 0), (3, 2)], True, dict(colour_weights=(0.5, 0.2, 0.3), fat_zero=0.0, sigma_rb=0.7,
                                          sigma_corr=1.2)),
    (None, tables.QUAD_PAIRS, False, dict(colour_weights=(1.0,), fat_zero=5.0, sigma_rb=0.5, sigma_corr=0.15)),
]


@pytest.mark.parametrize("cfa, pairs, inside, kwargs", CORRELATE_CASES)
def test_correlate_equals_reference(cfa, pairs, inside, kwargs):
    # Input: the reference CLT rounded to float32, so this checks the correlate stage alone.
    frames, centres = random_case(2, inside=inside)
    clt = reference_clt(frames, centres, cfa)
    got = numpy_tp.numpy_correlate(clt.astype(np.float32), pairs, **kwargs)
    want = np.stack([ref.correlate(clt[:, a], clt[:, b], **kwargs) for a, b in pairs], axis=1)
    assert got.dtype == np.float32
    assert got.shape == (40, len(pairs), 15, 15)
    assert relative_error(got, want) <= TOL


def test_correlate_zero_tiles_without_fat_zero_are_zero():
    clt = np.zeros((2, 2, 3, 4, 8, 8), dtype=np.float32)
    clt[1] = np.random.default_rng(3).standard_normal((2, 3, 4, 8, 8))
    corr = numpy_tp.numpy_correlate(clt, [(0, 1)], (0.25, 0.25, 0.5), 0.0, 0.5, 0.9)
    assert np.all(corr[0] == 0.0)
    assert np.all(np.isfinite(corr)) and np.abs(corr[1]).max() > 0


def test_full_pipeline_defaults_equal_reference():
    # numpy_convert -> numpy_correlate with the defaults (GPU-path constants) vs the reference chain.
    frames, centres = random_case(4, inside=True)
    got = numpy_tp.numpy_correlate(numpy_tp.numpy_convert(frames, centres, "GRBG"))
    clt = reference_clt(frames, centres, "GRBG")
    want = np.stack([ref.correlate(clt[:, a], clt[:, b]) for a, b in tables.QUAD_PAIRS], axis=1)
    assert relative_error(got, want) <= TOL


def imported_names(module) -> list[str]:
    """Every module and name ``module``'s source imports, relative imports resolved to absolute names."""
    tree = ast.parse(Path(module.__file__).read_text())
    names = [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
    for n in ast.walk(tree):
        if isinstance(n, ast.ImportFrom):
            base = importlib.util.resolve_name("." * n.level + (n.module or ""), module.__package__) if n.level \
                else n.module
            names += [base] + [f"{base}.{a.name}" for a in n.names]
    return names


def test_imported_names_sees_relative_imports():
    # The check below must not miss ``from ... import reference`` written relative to the twins' package.
    assert "tpnet_gpu.bench.twins.common.basis_expansion" in imported_names(numpy_tp)
    assert "tpnet_gpu.operators" in imported_names(numpy_tp)


@pytest.mark.parametrize("module", [numpy_tp, twins_common], ids=lambda m: m.__name__.rpartition(".")[2])
def test_peer_does_not_import_the_reference(module):
    names = imported_names(module)
    assert not [m for m in names if m.startswith("tpnet_gpu.reference")], names
