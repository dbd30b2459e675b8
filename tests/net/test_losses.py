"""TPNET losses (net/losses.py) against hand-computed cases (numbers written out below; float64, atol 1e-12
unless noted), the cluster form of S for its frame form, and the composition of the total loss.
"""

import math

import pytest
import torch

from tpnet_gpu.net.losses import (
    RING_CLUSTER_INDEX,
    RING_OFFSETS,
    main_loss,
    mirror_loss,
    mirror_loss_frame,
    total_loss,
    weights_loss,
)
from tpnet_gpu.net.model import TPNet

F64 = torch.float64
ATOL = 1e-12
A, B = 1 / 6.8, 0.7 / 6.8  # W-loss neighbour coefficients (orthogonal, diagonal)



def t64(*values):
    return torch.tensor(values, dtype=F64)


def close(got, want, atol=ATOL):
    torch.testing.assert_close(got, torch.as_tensor(want, dtype=got.dtype), atol=atol, rtol=0)


# ------------------------------------------------------------------------------------------------ G
# Three tiles: s = (0.58, 0.28, 0.08) -> w = max(s - 0.08, 0)^2 = (0.25, 0.04, 0);
# t = (0.5, 4, 10) -> k = 8 / clip(t, 1, 8) = (8, 2, 1); W ~ k w = (2.0, 0.08, 0);
# errors p - g = (0.1, 0.5, 3.0) -> squared (0.01, 0.25, 9): G = (2*0.01 + 0.08*0.25) / 2.08 = 0.04 / 2.08.
PRED, GT, S, T = t64(1.1, 2.5, 6.0), t64(1.0, 2.0, 3.0), t64(0.58, 0.28, 0.08), t64(0.5, 4.0, 10.0)


def test_main_loss_hand_case():
    close(main_loss(PRED, GT, S, T), 0.04 / 2.08)
    # tile_weight (1, 3, 5): W ~ (2.0, 0.24, 0) -> (0.02 + 0.06) / 2.24
    close(main_loss(PRED, GT, S, T, tile_weight=t64(1, 3, 5)), 0.08 / 2.24)
    # disp_wmax 4: k = 4 / clip(t, 1, 4) = (4, 1, 1); W ~ (1.0, 0.04, 0) -> (0.01 + 0.01) / 1.04
    close(main_loss(PRED, GT, S, T, disp_wmax=4.0), 0.02 / 1.04)
    # conf_pwr 1: w = (0.5, 0.2, 0); W ~ (4, 0.4, 0) -> (0.04 + 0.1) / 4.4
    close(main_loss(PRED, GT, S, T, conf_pwr=1.0), 0.14 / 4.4)
    # any shape: flattened
    close(main_loss(PRED[None], GT[None], S[None], T[None]), 0.04 / 2.08)


def test_main_loss_ignores_nan_tiles_and_guards_zero_weight():
    # A 4th tile with NaN ground truth (else heavy) changes nothing, and its gradient is 0, not NaN.
    pred = t64(1.1, 2.5, 6.0, 7.0).requires_grad_()
    loss = main_loss(pred, t64(1.0, 2.0, 3.0, math.nan), t64(0.58, 0.28, 0.08, 1.0), t64(0.5, 4.0, 10.0, 2.0))
    close(loss, 0.04 / 2.08)
    loss.backward()
    close(pred.grad, t64(2 * 0.1 * 2 / 2.08, 2 * 0.5 * 0.08 / 2.08, 0, 0))
    # All strengths <= 0.08: loss 0 with a graph and zero gradients.
    pred = PRED.clone().requires_grad_()
    loss = main_loss(pred, GT, t64(0.05, 0.0, 0.08), T)
    assert loss.requires_grad and loss == 0
    loss.backward()
    assert torch.equal(pred.grad, torch.zeros(3, dtype=F64))


# ------------------------------------------------------------------------------------------------ S
# One cluster: orthogonal neighbours g = 1, diagonal g = 2, all strength 1 ->
# m = (4*1*1 + 4*0.7*2) / (4 + 4*0.7) = 9.6 / 6.8 = 24/17. Centre g = m + 0.15 -> D = 0.15.
M = 24 / 17
RING_GT = t64(*[2.0 if dy and dx else 1.0 for dy, dx in RING_OFFSETS])[None]
RING_S = torch.ones(1, 8, dtype=F64)


def s_one(p, g, ring_gt=RING_GT, ring_s=RING_S, **kw):
    return mirror_loss(t64(p), t64(g), t64(0.6), ring_gt, ring_s, **kw)


def test_mirror_loss_hand_case():
    g = M + 0.15
    close(s_one(g, g), 0.0)  # at the ground truth
    close(s_one(2 * M - g, g), 0.0)  # at the mirror 2m - g
    close(s_one(M, g), 0.15)  # at the neighbour mean: D
    close(s_one(M + 0.075, g), 0.15 - 0.075**2 / 0.15)  # 0.1125 on the parabola
    close(s_one(g + 0.5, g), 0.0)  # outside [2m - g, g]
    close(s_one(M, M + 0.5), 0.2)  # D = 0.5 clipped at 0.2
    close(s_one(M, M + 0.5, clip=1.0), 0.5)
    close(s_one(M, M), 0.001)  # D floored at 0.001
    # Diagonal strengths 0 -> m = 1 (orthogonal mean only): p = 1, g = 1.3 -> 0.3, clipped to 0.2; g = 1.1 -> 0.1.
    diag_off = t64(*[0.0 if dy and dx else 1.0 for dy, dx in RING_OFFSETS])[None]
    close(s_one(1.0, 1.1, ring_s=diag_off), 0.1)
    # Two clusters, centre strengths (1, 0.5), costs (0.15, 0.1125): S = (0.15 + 0.5*0.1125) / 1.5 = 0.1375.
    loss = mirror_loss(t64(M, M + 0.075), t64(M + 0.15, M + 0.15), t64(1.0, 0.5), RING_GT.repeat(2, 1),
                       RING_S.repeat(2, 1))
    close(loss, 0.1375)


def test_mirror_loss_zero_neighbour_weight_is_zero_not_nan():
    pred = t64(M).requires_grad_()
    loss = mirror_loss(pred, t64(M + 0.15), t64(0.6), RING_GT, torch.zeros(1, 8, dtype=F64))
    loss.backward()
    assert loss == 0 and pred.grad == 0


def test_mirror_loss_frame_equals_cluster_form():
    # Oracle: mirror_loss on ring neighbours cut with clipped indices (loops); float64, atol 1e-12.
    g = torch.Generator().manual_seed(5)
    ty, tx = 5, 6
    gt = torch.rand(ty, tx, generator=g, dtype=F64) * 3
    strength = torch.rand(ty, tx, generator=g, dtype=F64)
    pred = gt + (torch.rand(ty, tx, generator=g, dtype=F64) - 0.5) * 0.6
    ring = [[(min(max(y + dy, 0), ty - 1), min(max(x + dx, 0), tx - 1)) for dy, dx in RING_OFFSETS]
            for y in range(ty) for x in range(tx)]
    n_gt = torch.stack([torch.stack([gt[i] for i in r]) for r in ring])
    n_s = torch.stack([torch.stack([strength[i] for i in r]) for r in ring])
    want = mirror_loss(pred.flatten(), gt.flatten(), strength.flatten(), n_gt, n_s)
    close(mirror_loss_frame(pred, gt, strength), want)
    assert want > 0.01
    assert RING_CLUSTER_INDEX == (6, 7, 8, 11, 13, 16, 17, 18)


# ------------------------------------------------------------------------------------------------ W
def test_weights_loss_spike():
    # One output unit, a single 1 at the centre of layer 0. Zero borders. diff: 1 at the spike; as coded,
    # left/right neighbours see it twice (-2a each), up/down never (0), diagonals -b each:
    #   as_coded  sum diff^2 = 1 + 2*(2a)^2 + 4*b^2;  isotropic = 1 + 4*a^2 + 4*b^2.
    # mean over 4*81 = 324 correlation weights / mean(W^2) over 325 = 1/325.
    w = torch.zeros(1, 325, dtype=F64)
    w[0, 0 * 81 + 4 * 9 + 4] = 1.0
    as_coded = (1 + 8 * A**2 + 4 * B**2) / 324 * 325  # 1.21915...
    isotropic = (1 + 4 * A**2 + 4 * B**2) / 324 * 325  # 1.13238...
    close(weights_loss(w), as_coded)
    close(weights_loss(w, mode="isotropic"), isotropic)
    assert abs(as_coded - 1.21915) < 1e-5 and abs(isotropic - 1.13238) < 1e-5
    w[0, 324] = 1.0  # the target column only enters the denominator: 2/325
    close(weights_loss(w), as_coded / 2)
    close(weights_loss(3.0 * w), as_coded / 2)  # scale-invariant


def test_weights_loss_constant_maps():
    # All 324 correlation weights 1 (target 0). Replicate borders: every neighbour average is 1 -> 0.
    # Zero borders (per 9x9 map, /6.8 throughout): interior 0; as coded, top/bottom edge cells (14) miss
    # 2 diagonals: diff 1.4; left/right edge cells (14) miss one left/right (counted twice) + 2 diagonals:
    # 3.4; corners (4): 4.1. Isotropic: every edge cell 2.4, corners 4.1.
    w = torch.ones(1, 325, dtype=F64)
    w[0, 324] = 0.0
    close(weights_loss(w, zero_borders=False), 0.0)
    close(weights_loss(w, mode="isotropic", zero_borders=False), 0.0)
    per_map = {"as_coded": 14 * 1.4**2 + 14 * 3.4**2 + 4 * 4.1**2, "isotropic": 28 * 2.4**2 + 4 * 4.1**2}
    for mode, ss in per_map.items():
        close(weights_loss(w, mode=mode), (4 * ss / 6.8**2 / 324) / (324 / 325))


def test_weights_loss_reads_the_layers_columns_only():
    # One layer (a binocular rig) and 25 more inputs after the target: the spike of test_weights_loss_spike in
    # the one 9x9 map gives (1 + 8a^2 + 4b^2) / 81 over mean(W^2) = 1/107; a 1 in the extra inputs only enters
    # the denominator (as the target column does); the 4-layer reading of the same columns would differ.
    w = torch.zeros(1, 81 + 1 + 25, dtype=F64)
    w[0, 4 * 9 + 4] = 1.0
    one_layer = (1 + 8 * A**2 + 4 * B**2) / 81 * 107
    close(weights_loss(w, layers=1), one_layer)
    w[0, 81 + 1 + 7] = 1.0
    close(weights_loss(w, layers=1), one_layer / 2)
    wide = torch.zeros(1, 325 + 25, dtype=F64)
    wide[0, 2 * 81 + 4 * 9 + 4] = 1.0  # layer 2's centre of a quad network with 25 extra inputs
    close(weights_loss(wide), (1 + 8 * A**2 + 4 * B**2) / 324 * 350)
    with pytest.raises(ValueError, match=r"first_layer_weight: expected shape \(out, > 81\) for 1 layers"):
        weights_loss(torch.zeros(2, 81), layers=1)


def test_weights_loss_zero_weights_is_zero():
    assert weights_loss(torch.zeros(2, 325)) == 0


# -------------------------------------------------------------------------------------------- total
def _cluster_batch(seed, b=6):
    g = torch.Generator().manual_seed(seed)
    target = torch.rand(b, generator=g) * 6
    gt = target + torch.randn(b, generator=g) * 0.5
    strength = torch.rand(b, generator=g) * 0.8 + 0.2
    n_gt = gt[:, None] + torch.randn(b, 8, generator=g) * 0.3
    n_s = torch.rand(b, 8, generator=g)
    return target, gt, strength, n_gt, n_s


def test_total_loss_composition_cluster_and_frame():
    # Oracle: the components recomputed one by one; pi = [2, 0.5, 0.2] / 2.7; atol 1e-6 (float32).
    torch.manual_seed(6)
    net = TPNet()
    target, gt, strength, n_gt, n_s = _cluster_batch(6)
    residual = torch.randn(6, 3) * 0.3
    u = n_s * torch.tensor([0.7 if dy and dx else 1.0 for dy, dx in RING_OFFSETS])
    m = (u * n_gt).sum(1) / u.sum(1)
    residual[:, 0] = (gt + m) / 2 - target  # clone 0 halfway to the neighbour mean: S > 0
    terms = total_loss(residual, target, gt, strength, net.first_layer_weight, neighbour_gt=n_gt,
                       neighbour_strength=n_s)
    pred = target[:, None] + residual
    pi = [2 / 2.7, 0.5 / 2.7, 0.2 / 2.7]
    mains = [main_loss(pred[:, n], gt, strength, target) for n in range(3)]
    s = mirror_loss(pred[:, 0], gt, strength, n_gt, n_s)
    w = weights_loss(net.first_layer_weight)
    want = sum(p * m for p, m in zip(pi, mains)) + 0.1 * s + 0.5 * w
    close(terms.total, want, atol=1e-6)
    close(terms.main, torch.stack(mains), atol=1e-6)
    assert terms.mirror > 0 and terms.weights > 0.5
    # Frame form: (ty, tx, 3) residual, S from the dense ring.
    grid = (4, 5)
    t, g_, s_ = (torch.rand(*grid) * 4 for _ in range(3))
    res = torch.randn(*grid, 3) * 0.3
    terms = total_loss(res, t, g_, s_, net.first_layer_weight, partial_weights=(1.0, 1.0, 2.0))
    pred = t[..., None] + res
    want = (0.25 * main_loss(pred[..., 0], g_, s_, t) + 0.25 * main_loss(pred[..., 1], g_, s_, t)
            + 0.5 * main_loss(pred[..., 2], g_, s_, t) + 0.1 * mirror_loss_frame(pred[..., 0], g_, s_) + 0.5 * w)
    close(terms.total, want, atol=1e-6)


@pytest.mark.parametrize("form", ["cluster", "frame"])
def test_total_loss_gradients_reach_every_parameter(form):
    torch.manual_seed(7)
    net = TPNet()
    if form == "cluster":
        target, gt, strength, n_gt, n_s = _cluster_batch(7, b=4)
        x = torch.randn(4, 25, 325)
        x[:, 12, 324] = target
        terms = total_loss(net(x), target, gt, strength, net.first_layer_weight, neighbour_gt=n_gt,
                           neighbour_strength=n_s)
    else:
        layers, target = torch.randn(4, 5, 4, 9, 9), torch.rand(4, 5) * 4
        residual = net.forward_frame(layers, target, clone=(0, 1, 2))
        terms = total_loss(residual, target, target + 0.3, torch.full_like(target, 0.9), net.first_layer_weight)
    terms.total.backward()
    for name, p in net.named_parameters():
        assert p.grad is not None and p.grad.abs().sum() > 0, name


def test_losses_reject_bad_input():
    with pytest.raises(ValueError, match=r"gt: expected shape \(3,\) \(that of pred\), got \(2,\)"):
        main_loss(PRED, GT[:2], S, T)
    with pytest.raises(TypeError, match="target: expected a floating-point tensor, got torch.int64"):
        main_loss(PRED, GT, S, torch.tensor([1, 2, 3]))
    with pytest.raises(ValueError, match=r"devices do not match \(meta vs cpu of pred\)"):
        main_loss(PRED, GT.to("meta"), S, T)
    with pytest.raises(ValueError, match=r"neighbour_gt: expected shape \(1, 8\), got \(1, 7\)"):
        mirror_loss(t64(1.0), t64(1.0), t64(1.0), RING_GT[:, :7], RING_S[:, :7])
    with pytest.raises(ValueError, match="mode: expected one of \\('as_coded', 'isotropic'\\), got 'iso'"):
        weights_loss(torch.zeros(2, 325), mode="iso")
    with pytest.raises(ValueError, match=r"first_layer_weight: expected shape \(out, > 324\) for 4 layers and the target, got \(325, 256\)"):
        weights_loss(torch.zeros(325, 256))
    with pytest.raises(ValueError, match="partial_weights: expected 3 weights"):
        total_loss(torch.zeros(2, 3), T[:2], GT[:2], S[:2], torch.zeros(1, 325, dtype=F64), partial_weights=(1,))
    with pytest.raises(ValueError, match="neighbour_gt, neighbour_strength: expected both or neither"):
        total_loss(torch.zeros(2, 3), T[:2], GT[:2], S[:2], torch.zeros(1, 325), neighbour_gt=torch.zeros(2, 8))
