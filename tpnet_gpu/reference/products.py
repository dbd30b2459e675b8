"""Golden reference: point-wise products of CLT tiles (tile_processor.md §5.2, §5.3, §6.2). Float64, NumPy.

A CLT tile ``[..., 4, 8, 8]`` is read as a bicomplex number per frequency, Q = CC + i SC + j CS + ij SS with
i^2 = j^2 = -1 and ij = ji: i carries the horizontal sine, j the vertical one.
"""

from __future__ import annotations

import numpy as np

from tpnet_gpu import tables


def _check_clt(name: str, x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if x.shape[-3:] != (4, tables.DTT_SIZE, tables.DTT_SIZE):
        raise ValueError(f"{name}: expected shape (..., 4, 8, 8), got {x.shape}")
    return x


def bmul(a, b) -> np.ndarray:
    """Bicomplex product ``a * b`` per frequency, ``[..., 4, 8, 8]`` (broadcasts over leading axes).

    This is the convolution product of §5.2 (``a`` = kernel, ``b`` = image tile).
    """
    a, b = _check_clt("a", a), _check_clt("b", b)
    a0, a1, a2, a3 = (a[..., q, :, :] for q in range(4))
    b0, b1, b2, b3 = (b[..., q, :, :] for q in range(4))
    return np.stack(
        [
            a0 * b0 - a1 * b1 - a2 * b2 + a3 * b3,
            a0 * b1 + a1 * b0 - a2 * b3 - a3 * b2,
            a0 * b2 + a2 * b0 - a1 * b3 - a3 * b1,
            a0 * b3 + a3 * b0 + a1 * b2 + a2 * b1,
        ],
        axis=-3,
    )


def bconj(a) -> np.ndarray:
    """Bicomplex conjugate used by the correlation: (CC, -SC, -CS, SS), ``[..., 4, 8, 8]``."""
    a = _check_clt("a", a)
    return a * np.array([1.0, -1.0, -1.0, 1.0])[:, None, None]


def correlation_product(first, second) -> np.ndarray:
    """``conj(first) * second`` per frequency (§6.2): the spectrum of sum_x f1(x) f2(x + s), ``[..., 4, 8, 8]``."""
    return bmul(bconj(first), second)
