"""Known misalignments for tests and benches: a random, gauge-free correction vector scaled so that the frame
edge moves by a given number of pixels (``model.edge_misalignment`` from the ideal rig)."""

from __future__ import annotations

import numpy as np

from tpnet_gpu.calibration import model
from tpnet_gpu.camera import EXTRINSIC_TERMS, Rig


def misalignment(rig: Rig, edge_px: float, seed: int = 0) -> np.ndarray:
    """``(13,)`` corrections without gauge components moving ``rig``'s frame edge by ``edge_px`` at most."""
    if not edge_px > 0:
        raise ValueError(f"edge_px: expected a positive number of pixels, got {edge_px}")
    rng = np.random.default_rng(seed)
    e = model.observable_part(rig, rng.normal(size=EXTRINSIC_TERMS) / rig.focal_px)
    zero = np.zeros(EXTRINSIC_TERMS)
    return e * edge_px / model.edge_misalignment(rig, e, zero)  # small angles: the movement is linear in e
