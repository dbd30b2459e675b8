"""Operations on the tile grid (tpnet_gpu/disparity/grid.py). Oracles: physical (a depth step seen by a 16 px
window at stride 8) and hand-computed strength-weighted means; exact up to float32 rounding."""

import pytest
import torch

from tpnet_gpu.disparity.grid import fill, grow, settle, two_depth


def test_two_depth_flags_tiles_beside_a_depth_step():
    """Physical oracle: a 2 px step between tile columns 3 and 4 (a window 16 px wide at stride 8 sees both
    sides) flags the tiles of columns 3 and 4 only; a ramp of 0.4 px per tile (spread 0.8 px) flags nothing;
    unmeasured tiles are never flagged and do not count as neighbours (an unmeasured column 3 hides the step)."""
    grid = torch.zeros(5, 8)
    grid[:, 4:] = 2.0
    flags = two_depth(grid)
    assert flags[:, 3:5].all() and not flags[:, :3].any() and not flags[:, 5:].any()
    assert not two_depth(0.4 * torch.arange(8.0).expand(5, 8)).any()
    grid[:, 3] = float("nan")
    flags = two_depth(grid)
    assert not flags.any()


def test_settle_moves_only_weak_outliers_on_a_surface():
    """Oracle: hand-computed strength-weighted means. A plane at 5.0 px (strength 0.5) with 0.2 px of stripes;
    a weak tile (0.1) at 7.0 px takes the mean of the 8 surface tiles around it (it is off the surface band of
    1.5 px, so its own value does not count); the same tile strong (0.5) keeps 7.0; a weak tile 1.3 px off its
    surface (within the band: on it) takes the strength-weighted mean with itself in it; a weak tile 0.4 px from
    its surface mean keeps its value
    (within ``WEAK_OFF``); a weak tile on a 1-tile-wide ridge of 9 px (3 of its 9 neighbourhood tiles) keeps
    it; unmeasured tiles stay NaN."""
    grid = torch.full((7, 9), 5.0)
    grid[:, ::2] += 0.2
    strength = torch.full((7, 9), 0.5)
    grid[2, 2], strength[2, 2] = 7.0, 0.1  # weak outlier
    grid[2, 5], strength[2, 5] = 7.0, 0.5  # strong: its own peak
    grid[5, 4], strength[5, 4] = 6.5, 0.1  # weak, 1.3 px off: on the surface band
    grid[4, 2], strength[4, 2] = grid[4, 2] + 0.3, 0.1  # weak, 0.4 px from its surface: within WEAK_OFF
    grid[:, 7], strength[5, 7] = 9.0, 0.1  # a ridge one tile wide
    grid[0, 0] = float("nan")
    settled = settle(grid, strength)
    ring = [grid[y, x] for y in (1, 2, 3) for x in (1, 2, 3) if (y, x) != (2, 2)]
    assert settled[2, 2] == pytest.approx(float(sum(ring)) / 8, abs=1e-6)  # equal strengths: the plain mean
    assert settled[2, 5] == 7.0 and settled[4, 2] == grid[4, 2] and settled[5, 7] == 9.0
    around = [(grid[y, x], strength[y, x]) for y in (4, 5, 6) for x in (3, 4, 5)]
    weighted = sum(float(g) * float(w) for g, w in around) / sum(float(w) for _, w in around)
    assert settled[5, 4] == pytest.approx(weighted, abs=1e-6)
    assert torch.isnan(settled[0, 0])
    unchanged = torch.ones(7, 9, dtype=torch.bool)
    unchanged[2, 2] = unchanged[0, 0] = unchanged[5, 4] = False
    assert torch.equal(settled[unchanged], grid[unchanged])


def test_fill_gives_unmeasured_tiles_their_surface_where_the_first_stage_was_clear():
    """Oracle: hand-computed strength-weighted means. On a plane at 3.0 px with 0.2 px stripes (strengths 0.2 and
    0.6), an unmeasured tile whose clear first-stage answer (3.3) agrees with its neighbours takes the
    strength-weighted mean of the 8 of them; beside a 9 px block only the neighbours within 1 px of its answer
    count; an unclear answer, or one more than 1 px from the neighbours' median (5.0), leaves NaN; measured tiles
    keep their values."""
    grid = torch.full((6, 8), 3.0)
    grid[:, ::2] += 0.2
    strength = torch.where(torch.arange(8) % 2 == 0, 0.6, 0.2).expand(6, 8).clone()
    grid[:, 6:] = 9.0
    search = torch.full((6, 8), 3.3)
    clear = torch.ones(6, 8, dtype=torch.bool)
    holes = [(2, 2), (2, 5), (4, 3), (1, 3)]
    for y, x in holes:
        grid[y, x] = float("nan")
    search[4, 3] = 5.0  # disagrees with the neighbours' median (3.0-3.2)
    clear[1, 3] = False
    filled = fill(grid, strength, search, clear)

    def mean_near(y, x, answer):
        near = [(float(grid[v, u]), float(strength[v, u])) for v in (y - 1, y, y + 1) for u in (x - 1, x, x + 1)
                if (v, u) != (y, x) and abs(float(grid[v, u]) - answer) <= 1.0]
        return sum(g * w for g, w in near) / sum(w for _, w in near)

    assert filled[2, 2] == pytest.approx(mean_near(2, 2, 3.3), abs=1e-6)
    assert filled[2, 5] == pytest.approx(mean_near(2, 5, 3.3), abs=1e-6)  # the 9 px column left out
    assert torch.isnan(filled[4, 3]) and torch.isnan(filled[1, 3])
    measured = torch.isfinite(grid)
    assert torch.equal(filled[measured], grid[measured])


@pytest.mark.parametrize("radius", [0, 1, 2, 4, 9])
def test_grow_is_a_square_dilation(radius):
    """Oracle: torch's max pooling over a (2 radius + 1)^2 window (zero padding) of a random sparse mask; grids
    narrower than the square included; the result is written into the given buffer."""
    g = torch.Generator().manual_seed(radius)
    for shape in [(9, 13), (1, 6), (30, 21)]:
        mask = torch.rand(shape, generator=g) < 0.05
        mask[shape[0] // 2, shape[1] // 3] = True
        out, scratch = torch.empty(shape, dtype=torch.bool), torch.empty(shape, dtype=torch.bool)
        expected = torch.nn.functional.max_pool2d(mask.float()[None, None], 2 * radius + 1, 1, radius)[0, 0] > 0
        assert grow(mask, radius, out, scratch) is out
        assert torch.equal(out, expected)
