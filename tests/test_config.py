"""The settings' one home (tpnet_gpu/config.py): the disparity range searched, its default and its refusals.
Oracle: the pinhole law d = f B / (Z p) written out with the quad's numbers, and the argument rules."""

import pytest

from tpnet_gpu.camera import Rig
from tpnet_gpu.config import EngineConfig, disparity_range


def test_the_default_range_ends_at_the_nearest_distance():
    rig = Rig()
    expected = rig.focal_mm * rig.baseline_mm / (1000.0 * EngineConfig().nearest_m * rig.pixel_size_mm)
    low, high = disparity_range(None, None, rig, EngineConfig().nearest_m)
    assert low == 0.0 and high == pytest.approx(expected, rel=1e-12)
    assert disparity_range(-2, 7.5, rig, 8.0) == (-2.0, 7.5)


@pytest.mark.parametrize("low, high, match", [
    (0.0, float("nan"), r"max_disparity: expected a finite number of pixels, got nan"),
    (float("-inf"), 4.0, r"min_disparity: expected a finite number of pixels, got -inf"),
    (True, 4.0, r"min_disparity: expected a finite number of pixels, got True"),
    ("1", 4.0, r"min_disparity: expected a finite number of pixels, got '1'"),
    (3.0, 1.0, r"max_disparity: expected more than min_disparity=3, got 1"),
    (1e6, None, r"max_disparity: expected more than min_disparity=1e\+06, got .* \(the rig's disparity at 8 m\)"),
])
def test_bad_ranges_are_refused_naming_the_argument(low, high, match):
    with pytest.raises(ValueError, match=match):
        disparity_range(low, high, Rig(), 8.0)
