"""The robust LMA (tpnet_gpu/calibration/lma.py) on observations drawn from the rig model (``Rig.port_coordinates``
with known corrections and disparities): noise 0.05 px, 20 % gross tiles (lags off by 2-5 px), start disparities
off by up to 1 px. Oracle: the known corrections, to 0.02 px at the frame edge. Break tried: Cauchy weights
replaced by 1 (plain least squares: the gross tiles pull the fit ~0.2 px off, the test fails)."""

import numpy as np
import pytest

from tpnet_gpu import tables
from tpnet_gpu.calibration import model
from tpnet_gpu.calibration.lma import Observations, fit
from tpnet_gpu.calibration.measure import tile_grid_centres
from tpnet_gpu.calibration.synthetic import misalignment
from tpnet_gpu.camera import Rig


@pytest.mark.parametrize("level", [0.4, 2.5])
def test_recovers_known_corrections_despite_gross_tiles(level):
    rig = Rig(width=320, height=240)
    rng = np.random.default_rng(5)
    truth = misalignment(rig, level, seed=7)
    centre = tile_grid_centres(rig)
    true_d = rng.uniform(0.0, 30.0, len(centre))
    d = true_d + rng.uniform(-1.0, 1.0, len(centre))
    reference = model.pair_differences(rig.port_coordinates(centre, d), tables.QUAD_PAIRS)
    lags = model.pair_differences(model.ports(rig, truth, centre, true_d), tables.QUAD_PAIRS) - reference
    lags += rng.normal(0.0, 0.05, lags.shape)
    gross = rng.random(len(centre)) < 0.2
    lags[gross] += rng.uniform(2.0, 5.0, lags[gross].shape) * rng.choice([-1, 1], lags[gross].shape)
    found, summary = fit(rig, np.zeros(13), Observations(centre, d, lags, reference), tables.QUAD_PAIRS)
    assert model.edge_misalignment(rig, found, truth) < 0.02
    assert summary["cost"][1] < summary["cost"][0]
