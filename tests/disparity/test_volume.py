"""Cost volume and SGM aggregation (tpnet_gpu/disparity/volume.py). Oracles: hand-built volumes whose best
answers are known (a plane with one corrupted tile; a step edge), the parabola vertex, and the SGM recurrence
written out tile by tile in float64 (``sgm_oracle``)."""

import itertools

import numpy as np
import torch

from tpnet_gpu.disparity.volume import CostVolume, aggregate, pick


def plane_costs(shape=(9, 11), bins=21, true_bin=8) -> torch.Tensor:
    j = torch.arange(bins, dtype=torch.float32)
    return (0.02 * (j - true_bin) ** 2).clamp(max=1.0).expand(*shape, bins).clone()


def sgm_oracle(cost: np.ndarray, p1: float, p2: float) -> np.ndarray:
    """Hirschmueller's recurrence per direction and tile, in each direction's scan order, float64: L(p, d) =
    C(p, d) + min(L(q, d), L(q, d -+ 1) + p1, min_k L(q, k) + p2) - min_k L(q, k), q = p - r, L = C where q is
    outside the grid; summed over the 8 directions r."""
    height, width, bins = cost.shape
    total = np.zeros_like(cost, dtype=np.float64)
    for dy, dx in [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dy, dx) != (0, 0)]:
        path = np.zeros_like(total)
        ys = range(height) if dy >= 0 else range(height - 1, -1, -1)
        xs = range(width) if dx >= 0 else range(width - 1, -1, -1)
        for y, x in itertools.product(ys, xs):
            qy, qx = y - dy, x - dx
            if not (0 <= qy < height and 0 <= qx < width):
                path[y, x] = cost[y, x]
                continue
            q = path[qy, qx]
            for d in range(bins):
                near = min(q[d - 1] if d > 0 else np.inf, q[d + 1] if d < bins - 1 else np.inf) + p1
                path[y, x, d] = cost[y, x, d] + min(q[d], near, q.min() + p2) - q.min()
        total += path
    return total


def test_aggregation_equals_the_recurrence():
    """Random costs on a 5x7 grid (odd and even sides, so a row and a column meet in the middle), 6 bins:
    float32 against the float64 oracle within 1e-5."""
    cost = np.random.default_rng(0).random((5, 7, 6))
    got = aggregate(torch.tensor(cost, dtype=torch.float32), p1=0.1, p2=0.4).double().numpy()
    np.testing.assert_allclose(got, sgm_oracle(cost, 0.1, 0.4), atol=1e-5)


def test_aggregation_overrules_one_wrong_tile():
    cost = plane_costs()
    cost[4, 5] = 1.0
    cost[4, 5, 8] = 0.1  # the true disparity, slightly weaker than ...
    cost[4, 5, 17] = 0.0  # ... a false, sharp minimum (e.g. a periodic texture)
    d, _ = pick(cost, torch.arange(21, dtype=torch.float32), 1.0)
    assert abs(float(d[4, 5]) - 17) < 0.5  # alone, the tile takes its false minimum
    d, margin = pick(aggregate(cost, p1=0.05, p2=0.3), torch.arange(21, dtype=torch.float32), 1.0)
    assert torch.allclose(d, torch.full_like(d, 8.0), atol=0.05)
    assert (margin > 0).all()


def test_aggregation_keeps_a_strong_step_edge():
    cost = plane_costs()
    cost[:, 6:] = plane_costs(true_bin=15)[:, 6:]
    d, _ = pick(aggregate(cost, p1=0.05, p2=0.3), torch.arange(21, dtype=torch.float32), 1.0)
    assert torch.allclose(d[:, :6], torch.full_like(d[:, :6], 8.0), atol=0.05)
    assert torch.allclose(d[:, 6:], torch.full_like(d[:, 6:], 15.0), atol=0.05)


def test_pick_refines_to_the_parabola_vertex():
    j = torch.arange(11, dtype=torch.float32)
    cost = ((j - 4.3) ** 2)[None, None]
    d, _ = pick(cost, 10.0 + 0.5 * j, 0.5)
    assert abs(float(d) - (10.0 + 0.5 * 4.3)) < 1e-4


def test_volume_add_keeps_the_stronger_sample():
    volume = CostVolume((1, 2), 0.0, 4.0, 1.0, "cpu")
    offsets = torch.tensor([-1.0, 0.0, 1.0])
    volume.add(torch.tensor([[1.0, 2.0]]), offsets, torch.tensor([[0.1, 0.5, 0.2], [0.3, 0.3, 0.3]]), reach=1.0)
    volume.add(torch.tensor([[2.0, 2.0]]), offsets, torch.tensor([[0.9, 0.1, 0.0], [0.1, 0.1, 0.1]]), reach=1.0)
    v = volume.values[0]
    assert torch.allclose(v[0, :4], torch.tensor([0.1, 0.9, 0.2, 0.0]))  # bin 1: 0.5 then 0.9 -> 0.9
    assert torch.isneginf(v[0, 4]) and torch.allclose(v[1, 1:4], torch.tensor([0.3, 0.3, 0.3]))
    assert torch.isnan(volume.at(torch.tensor([[4.0, 0.0]]))[0, 0]) and float(volume.cost()[0, 0, 4]) == 1.0
    # a pass over chosen tiles only (flat numbers): tile 1 gets it, NaN targets and values are skipped
    volume.add(torch.tensor([0.0, float("nan")]), offsets, torch.tensor([[0.7, 0.8, float("nan")], [1.0] * 3]),
               reach=1.0, tiles=torch.tensor([1, 0]))
    assert torch.allclose(v[1, :2], torch.tensor([0.8, 0.3])) and torch.allclose(v[0, :4], torch.tensor([0.1, 0.9, 0.2, 0.0]))


def test_choose_is_pick_of_the_aggregation_without_changing_the_volume():
    """Oracle: a measured plane at bin 8 (disparity 4 px) with one corrupted tile: ``choose`` gives the plane
    everywhere, bitwise what ``pick(aggregate(cost))`` gives, and leaves the measured values as they were."""
    volume = CostVolume((9, 11), 0.0, 10.0, 0.5, "cpu")
    values = 1.0 - plane_costs(bins=volume.bins)
    values[4, 5, 17] = 1.0  # a false, sharp maximum
    values[:, :, -1] = float("-inf")  # not measured
    volume.values.copy_(values)
    d, margin = volume.choose(0.05, 0.3)
    want_d, want_margin = pick(aggregate(volume.cost(), 0.05, 0.3), volume.disparities, volume.step)
    assert torch.equal(d, want_d) and torch.equal(margin, want_margin)
    assert torch.allclose(d, torch.full_like(d, 4.0), atol=0.03)
    assert torch.equal(volume.values, values)
