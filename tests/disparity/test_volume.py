"""Cost volume and SGM aggregation (tpnet_gpu/disparity/volume.py). Oracles: hand-built volumes whose best
answers are known (a plane with one corrupted tile; a step edge), and the parabola vertex."""

import torch

from tpnet_gpu.disparity.volume import CostVolume, aggregate, pick


def plane_costs(shape=(9, 11), bins=21, true_bin=8) -> torch.Tensor:
    j = torch.arange(bins, dtype=torch.float32)
    return (0.02 * (j - true_bin) ** 2).clamp(max=1.0).expand(*shape, bins).clone()


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
