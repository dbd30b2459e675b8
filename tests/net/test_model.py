"""TPNet (net/model.py): the cluster form against the whole-frame form, clones, masks, devices, validation.

Oracles: the cluster form on 5x5 clusters cut with explicit, clipped neighbour indices (Python loops) for the
whole-frame form (atol 1e-5, float32; measured ~1e-7); per-tile loops for the relative targets (exact);
network.md §2-3 for the parameter counts; a "meta"
device and patched host-copy methods for "no host copy"; a synthetic residual for training.
"""

import math

import pytest
import torch

from tpnet_gpu.net.losses import main_loss
from tpnet_gpu.net.functional import (
    CENTRE,
    clusters_residual,
    gather_clusters,
    stage1_features,
    stage2_output,
    tile_inputs,
)
from tpnet_gpu.net.model import TPNet
from tpnet_gpu.net.neighbours import frame_relative_targets

ATOL = 1e-5
TY, TX = 7, 9



@pytest.fixture(params=["cpu", "cuda"])
def torch_device(request):
    if request.param == "cuda" and not torch.cuda.is_available():
        pytest.skip("no CUDA device for torch on this machine")
    return torch.device(request.param)


def _frame(seed=0, ty=TY, tx=TX, device="cpu", nan=True):
    g = torch.Generator().manual_seed(seed)
    layers = torch.randn(ty, tx, 4, 9, 9, generator=g)
    target = torch.rand(ty, tx, generator=g) * 6 - 1
    if nan:
        layers[1, 2, 3, 4, 5] = float("nan")
        target[0, 0] = float("nan")
    return layers.to(device), target.to(device)


def _raw_inputs(layers, target):
    """(ty, tx, 325) layers then target, NaN kept: the cluster form's own input (it reads the targets before
    NaN -> 0 for the relative targets)."""
    return torch.cat([layers.flatten(-3), target.unsqueeze(-1)], dim=-1)


def _clusters_by_loops(tile_map):
    """(ty*tx, 25, ...) in raster order of centres, neighbour indices clipped: the oracle's own cut."""
    ty, tx = tile_map.shape[:2]
    out = []
    for y in range(ty):
        for x in range(tx):
            out.append(torch.stack([tile_map[min(max(y + dy, 0), ty - 1), min(max(x + dx, 0), tx - 1)]
                                    for dy in range(-2, 3) for dx in range(-2, 3)]))
    return torch.stack(out)


def test_parameter_counts_and_init():
    # Oracle: network.md §3 (stage 1 = 120 480, stage 2 = 224 129 + 25 x 256 relative-target weights);
    # tf-slim init (Xavier-uniform, zero bias).
    net = TPNet()
    assert sum(p.numel() for p in net.stage1.parameters()) == 120_480
    assert sum(p.numel() for p in net.stage2.parameters()) == 224_129 + 25 * 256
    for layer in (*net.stage1, *net.stage2):
        bound = math.sqrt(6 / sum(layer.weight.shape))
        assert layer.weight.abs().max() <= bound
        if layer.weight.numel() >= 1000:  # uniform, not narrower: the extremes approach the bound
            assert layer.weight.abs().max() > 0.99 * bound
        assert torch.count_nonzero(layer.bias) == 0
    assert net.first_layer_weight is net.stage1[0].weight
    assert "stage1_widths=(256, 128, 32)" in repr(net)


def test_shapes():
    net = TPNet()
    layers, target = _frame()
    assert net(torch.randn(5, 25, 325)).shape == (5, 3)
    assert net.forward_frame(layers, target).shape == (TY, TX)
    assert net.forward_frame(layers, target, clone=(0, 2)).shape == (TY, TX, 2)
    assert net.forward_frame(layers.flatten(0, 1), target.flatten(), grid=(TY, TX)).shape == (TY, TX)
    assert net.predict_frame(layers, target, clone=[0, 1, 2]).shape == (TY, TX, 3)
    assert tile_inputs(layers, target).shape == (TY, TX, 325)


def test_tile_inputs_layout_and_nan():
    # Oracle: network.md §1 flattening [layer*81 + row*9 + col], target at 324, NaN -> 0.
    layers, target = _frame()
    x = tile_inputs(layers, target)
    assert x[2, 3, 1 * 81 + 4 * 9 + 7] == layers[2, 3, 1, 4, 7]
    assert x[2, 3, 324] == target[2, 3]
    assert x[1, 2, 3 * 81 + 4 * 9 + 5] == 0 and x[0, 0, 324] == 0
    assert not x.isnan().any()


def test_gather_clusters_equals_clipped_loops():
    x = tile_inputs(*_frame())
    ys, xs = torch.meshgrid(torch.arange(TY), torch.arange(TX), indexing="ij")
    assert torch.equal(gather_clusters(x, ys.flatten(), xs.flatten()), _clusters_by_loops(x))


@pytest.mark.parametrize("step_tiles", [None, 5, 20])
def test_frame_form_equals_cluster_form(torch_device, step_tiles, monkeypatch):
    """Oracle: forward_clusters on loop-cut clusters (edge tiles replicated by clipping); atol 1e-5. Also with
    the frame's stage 1 and stage 2 in steps of a few tiles (``STEP_TILES``: 5 -> 13 steps of stage 1 and one
    grid row per step of stage 2; 20 -> 4 and 2 rows)."""
    from tpnet_gpu.net import frame  # noqa: PLC0415

    if step_tiles is not None:
        monkeypatch.setattr(frame, "STEP_TILES", step_tiles)
    torch.manual_seed(1)
    net = TPNet().to(torch_device)
    layers, target = _frame(device=torch_device)
    clusters = _clusters_by_loops(_raw_inputs(layers, target))  # (63, 25, 325)
    with torch.no_grad():
        want = net.forward_clusters(clusters).view(TY, TX, 3)
        for clone in range(3):
            got = net.forward_frame(layers, target, clone=clone)
            assert got.device == torch_device
            torch.testing.assert_close(got, want[..., clone], atol=ATOL, rtol=0)
        torch.testing.assert_close(net.forward_frame(layers, target, clone=(0, 1, 2)), want, atol=ATOL, rtol=0)
        tile_major = net.forward_frame(layers.flatten(0, 1), target.flatten(), grid=(TY, TX), clone=(2, 0))
        torch.testing.assert_close(tile_major, want[..., [2, 0]], atol=ATOL, rtol=0)
        assert want.std() > 0.01  # not a degenerate (constant) output


def test_frame_form_with_inference_weights_and_new_weights():
    """Stage 2's kernels are made once per set of weights: weights made under ``torch.inference_mode`` (they keep
    no version counter) work, and weights changed in place are picked up. Oracle: forward_clusters; atol 1e-5."""
    torch.manual_seed(2)
    layers, target = _frame(device=torch.device("cpu"))
    clusters = _clusters_by_loops(_raw_inputs(layers, target))
    with torch.inference_mode():
        net = TPNet()
        net.load_state_dict({k: v.clone() for k, v in TPNet().state_dict().items()})
        want = net.forward_clusters(clusters).view(TY, TX, 3)
        torch.testing.assert_close(net.forward_frame(layers, target), want[..., 0], atol=ATOL, rtol=0)
    net = TPNet()
    with torch.no_grad():
        net.forward_frame(layers, target)
        net.stage2[0].weight.mul_(1.5)  # in place: same storage, a new version
        want = net.forward_clusters(clusters).view(TY, TX, 3)
        torch.testing.assert_close(net.forward_frame(layers, target), want[..., 0], atol=ATOL, rtol=0)


def test_clones_mask_neighbours():
    # Oracle: clone n ignores tiles outside its square -> changing a ring-2 tile moves only clone 0,
    # changing a ring-1 tile moves clones 0 and 1.
    torch.manual_seed(2)
    net = TPNet()
    x = torch.randn(1, 25, 325)
    base = net(x)
    ring2, ring1 = x.clone(), x.clone()
    ring2[0, 0] += 1.0  # (dy, dx) = (-2, -2)
    ring1[0, 6] += 1.0  # (-1, -1)
    d2, d1 = (net(ring2) - base).abs()[0], (net(ring1) - base).abs()[0]
    assert d2[0] > 0 and d2[1] == 0 and d2[2] == 0
    assert d1[0] > 0 and d1[1] > 0 and d1[2] == 0


def _relative_by_loops(target):
    """(ty*tx, 25) oracle of the relative targets: clipped neighbour indices, NaN -> 0, clip +-2 px."""
    ty, tx = target.shape
    out = torch.zeros(ty * tx, 25)
    for y in range(ty):
        for x in range(tx):
            for k, (dy, dx) in enumerate((dy, dx) for dy in range(-2, 3) for dx in range(-2, 3)):
                d = float(target[min(max(y + dy, 0), ty - 1), min(max(x + dx, 0), tx - 1)] - target[y, x])
                out[y * tx + x, k] = 0.0 if math.isnan(d) else min(max(d, -2.0), 2.0)
    return out


def test_relative_targets_equal_loops():
    # Oracle: _relative_by_loops (exact); targets spread over +-4 px so the clip is exercised.
    layers, target = _frame(seed=5)
    target = target * 2
    assert torch.equal(frame_relative_targets(target), _relative_by_loops(target))
    active = torch.ones(TY, TX, dtype=torch.bool)
    active[3, 4] = False
    inactive_nan = torch.where(active, target, torch.full_like(target, float("nan")))
    assert torch.equal(frame_relative_targets(target, active), _relative_by_loops(inactive_nan))
    got = frame_relative_targets(target)
    assert got.abs().max() == 2.0 and (got.abs() < 2.0).any()


def test_old_layout_weights_load_with_zero_relative_columns():
    # Oracle: a stage 2 without the relative-target inputs, computed by hand (stage2_output on the 800 features)
    # from the old weights, equals the model loaded from them.
    torch.manual_seed(4)
    net = TPNet()
    old = {k: v.clone() for k, v in net.state_dict().items()}
    old["stage2.0.weight"] = old["stage2.0.weight"][:, :800].clone()
    loaded = TPNet()
    loaded.load_state_dict(old)
    assert torch.count_nonzero(loaded.stage2[0].weight[:, 800:]) == 0
    layers, target = _frame(seed=4, nan=False)
    stage1 = [(m.weight, m.bias) for m in loaded.stage1]
    stage2 = [(old["stage2.0.weight"], old["stage2.0.bias"])] + [(m.weight, m.bias) for m in loaded.stage2[1:]]
    with torch.no_grad():
        feats = stage1_features(tile_inputs(layers, target), stage1)
        want = stage2_output(_clusters_by_loops(feats).flatten(1), stage2).view(TY, TX)
        torch.testing.assert_close(loaded.forward_frame(layers, target), want, atol=ATOL, rtol=0)


def test_active_mask_zeroes_stage1_features():
    # Oracle: stage 1 per tile, inactive tiles' features set to 0 and their relative targets to 0, loop-cut
    # clusters, stage 2 on each.
    torch.manual_seed(3)
    net = TPNet()
    layers, target = _frame(seed=3)
    active = torch.rand(TY, TX, generator=torch.Generator().manual_seed(3)) > 0.3
    active[0, :] = False  # an inactive edge row is replicated as zeros
    stage1 = [(m.weight, m.bias) for m in net.stage1]
    stage2 = [(m.weight, m.bias) for m in net.stage2]
    with torch.no_grad():
        feats = stage1_features(tile_inputs(layers, target), stage1) * active[..., None]
        relative = _relative_by_loops(torch.where(active, target, torch.full_like(target, float("nan"))))
        z = torch.cat([_clusters_by_loops(feats).flatten(1), relative], dim=1)
        want = stage2_output(z, stage2).view(TY, TX)
        got = net.forward_frame(layers, target, active=active)
    torch.testing.assert_close(got, want, atol=ATOL, rtol=0)
    assert (got - net.forward_frame(layers, target).detach()).abs().max() > 1e-3


def test_predict_frame_adds_target():
    net = TPNet()
    layers, target = _frame(nan=False)
    with torch.no_grad():
        torch.testing.assert_close(net.predict_frame(layers, target), target + net.forward_frame(layers, target))


def test_no_host_copy(monkeypatch):
    # Oracle: (1) the forward paths and losses run on the "meta" device (no data, any host copy raises);
    # (2) on CPU with Tensor.cpu/numpy/item/tolist patched to raise.
    net = TPNet().to("meta")
    layers, target = torch.empty(TY, TX, 4, 9, 9, device="meta"), torch.empty(TY, TX, device="meta")
    active = torch.empty(TY, TX, dtype=torch.bool, device="meta")
    assert net.forward_frame(layers, target, active=active, clone=(0, 1, 2)).device.type == "meta"
    assert net.predict_frame(layers, target).device.type == "meta"
    assert net(torch.empty(4, 25, 325, device="meta")).device.type == "meta"

    def boom(*args, **kwargs):
        raise AssertionError("host copy")

    for name in ("cpu", "numpy", "item", "tolist"):
        monkeypatch.setattr(torch.Tensor, name, boom)
    net = TPNet()
    layers, target = _frame()
    out = net.forward_frame(layers, target, clone=(0, 1, 2))
    loss = main_loss(target + out[..., 0], target + 0.1, torch.ones_like(target), target)
    loss.backward()
    assert out.device == layers.device


def test_rejects_bad_input():
    net = TPNet()
    layers, target = _frame()
    with pytest.raises(ValueError, match=r"x: expected shape \(B, 25, 325\), got \(2, 24, 325\)"):
        net(torch.zeros(2, 24, 325))
    with pytest.raises(TypeError, match="x: expected dtype torch.float32 .*, got torch.float64"):
        net(torch.zeros(2, 25, 325, dtype=torch.float64))
    with pytest.raises(ValueError, match=r"layers: expected shape \(ty, tx, 4, 9, 9\), or .* got \(63, 4, 9, 9\)"):
        net.forward_frame(layers.flatten(0, 1), target)
    with pytest.raises(ValueError, match=r"target: expected shape \(7, 9\), got \(9, 7\)"):
        net.forward_frame(layers, target.T)
    with pytest.raises(ValueError, match=r"layers: expected shape \(7, 8, 4, 9, 9\) or \(56, 4, 9, 9\)"):
        net.forward_frame(layers, target, grid=(7, 8))
    with pytest.raises(ValueError, match="clone: expected 0, 1, 2 or a non-empty sequence of them, got 3"):
        net.forward_frame(layers, target, clone=3)
    with pytest.raises(TypeError, match="active: expected dtype torch.bool, got torch.float32"):
        net.forward_frame(layers, target, active=torch.ones(TY, TX))
    with pytest.raises(ValueError, match=r"devices do not match \(meta vs cpu"):
        net.forward_frame(layers.to("meta"), target.to("meta"))
    with pytest.raises(TypeError, match="layers: expected a torch.Tensor, got ndarray"):
        net.forward_frame(layers.numpy(), target)
    with pytest.raises(ValueError, match="stage1_widths: expected a non-empty sequence of positive ints"):
        TPNet(stage1_widths=())


def test_short_training_lowers_loss():
    # Oracle: a synthetic true residual, a fixed random linear read-out of the centre tile's 324 correlation
    # values (std ~1 px); 300 Adam steps (lr 3e-3, 128 clusters) on a small TPNet must cut the main loss G
    # (clone 0) by >= 10x (measured: 1.7 -> ~1e-13).
    torch.manual_seed(4)
    g = torch.Generator().manual_seed(4)
    net = TPNet(stage1_widths=(32, 16, 8), stage2_widths=(32, 16, 8))
    x = torch.randn(128, 25, 325, generator=g)
    x[..., 324] = torch.rand(128, 25, generator=g) * 7 + 1
    readout = torch.randn(324, generator=g) / 18
    true_residual = x[:, CENTRE, :324] @ readout
    target = x[:, CENTRE, 324]
    gt, strength = target + true_residual, torch.ones(128)
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)

    def loss_fn():
        return main_loss(target + net(x)[:, 0], gt, strength, target)

    with torch.no_grad():
        start = loss_fn()
    for _ in range(300):
        opt.zero_grad()
        loss = loss_fn()
        loss.backward()
        opt.step()
    with torch.no_grad():
        end = loss_fn()
    assert end < start / 10, (start, end)


def test_functional_core_matches_module():
    net = TPNet()
    x = torch.randn(3, 25, 325)
    params = ([(m.weight, m.bias) for m in net.stage1], [(m.weight, m.bias) for m in net.stage2])
    torch.testing.assert_close(clusters_residual(x, *params), net(x), atol=0, rtol=0)


@pytest.mark.parametrize("layers", [1, 10])
def test_any_number_of_layers(layers):
    """TPNet(layers=G) reads G*81 + 1 inputs per tile; its two forms agree (oracle: forward_clusters on loop-cut
    clusters, atol 1e-5), and the other stages keep the quad's sizes."""
    torch.manual_seed(3)
    net = TPNet(layers=layers)
    assert net.first_layer_weight.shape == (256, layers * 81 + 1) and net.stage2[0].weight.shape == (256, 825)
    layers_t = torch.randn(TY, TX, layers, 9, 9)
    target = torch.rand(TY, TX) * 4
    clusters = _clusters_by_loops(_raw_inputs(layers_t, target))
    assert clusters.shape == (TY * TX, 25, layers * 81 + 1)
    with torch.no_grad():
        want = net.forward_clusters(clusters).view(TY, TX, 3)[..., 0]
        torch.testing.assert_close(net.forward_frame(layers_t, target), want, atol=ATOL, rtol=0)
    with pytest.raises(ValueError, match=rf"layers: expected shape \({TY}, {TX}, {layers}, 9, 9\) .* got"):
        net.forward_frame(torch.zeros(TY, TX, layers + 1, 9, 9), target)
    with pytest.raises(ValueError, match="layers: expected a positive number of correlation layers, got 0"):
        TPNet(layers=0)


def test_shipped_quad_weights_load_into_the_default_network():
    from tpnet_gpu.net.infer import DEFAULT_WEIGHTS  # noqa: PLC0415

    net = TPNet()
    net.load_state_dict(torch.load(DEFAULT_WEIGHTS, weights_only=True))
    assert net.layers == 4 and net.first_layer_weight.shape == (256, 325)
