"""The settings' one home (tpnet_gpu/config.py): the disparity range searched, its default and its refusals.
Oracle: the pinhole law d = f B / (Z p) written out with the quad's numbers, and the argument rules."""

import pytest

from tpnet_gpu.camera import Rig
from tpnet_gpu.config import DatasetSpec, EngineConfig, TrainConfig, disparity_range


def test_the_range_is_bound_by_the_frame():
    # the quad's cameras spread one baseline across and one down: a disparity d moves two cameras' windows d px
    # apart, so beyond the frame's side no tile has both on it (2592 across, 1936 down: the smaller bound holds);
    # a pair of 64 px bounds its default at the width, referenced to its centre or to either camera alike
    assert disparity_range(0, 1936, Rig(), 8.0) == (0.0, 1936.0)
    with pytest.raises(ValueError, match=r"max_disparity: expected at most 1936 px"):
        disparity_range(0, 1937, Rig(), 8.0)
    for offsets in (((0.0, 0.0), (1.0, 0.0)), ((-0.5, 0.0), (0.5, 0.0)), ((-1.0, 0.0), (0.0, 0.0))):
        pair = Rig(width=64, height=48, offsets=offsets)
        assert pair.disparity(8.0) > 64 and disparity_range(None, None, pair, 8.0) == (0.0, 64.0)


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
    (100.0, None, r"max_disparity: expected more than min_disparity=100, got .* \(the rig's disparity at 8 m\)"),
    (0.0, 1e308, r"max_disparity: expected at most 1936 px in magnitude \(beyond it a camera's tile windows leave the "
                 r"2592x1936 frame\), got 1e\+308"),
    (-4000.0, 4.0, r"min_disparity: expected at most 1936 px in magnitude"),
])
def test_bad_ranges_are_refused_naming_the_argument(low, high, match):
    with pytest.raises(ValueError, match=match):
        disparity_range(low, high, Rig(), 8.0)


@pytest.mark.parametrize("make, match", [
    (lambda: DatasetSpec(seed=-1), r"seed: expected an integer >= 0, got -1"),  # before: numpy's message
    (lambda: DatasetSpec(supersample=-1), r"supersample: expected an integer >= 1"),  # before: a traceback
    (lambda: DatasetSpec(scenes=2**70), r"scenes: expected an integer >= 1"),
    (lambda: DatasetSpec(test_fraction=1.0), r"test_fraction: expected a share in \[0, 1\)"),
    (lambda: TrainConfig(epochs=-1), r"epochs: expected an integer >= 1, got -1"),  # before: a traceback
    (lambda: TrainConfig(batch=0), r"batch: expected an integer >= 1"),
    (lambda: TrainConfig(seed=True), r"seed: expected an integer >= 0"),
])
def test_data_set_and_training_numbers_are_checked_naming_the_field(make, match):
    # issue 40 item 6: the hostile campaign's option bounds of `tpnet dataset` / `tpnet train` found these
    with pytest.raises(ValueError, match=match):
        make()
