"""Rendered rectified image pairs (tpnet_gpu/scenes/image_pairs.py). Every oracle is a physical fact or a closed
form, independent of the renderer's own output (tolerances beside each):

* geometry_and_lma.md E: a fronto-parallel plane at distance Z has disparity d = f B / (Z p) wherever it covers
  the left view (rtol 1e-9), NaN on the sky; a plane bounded to w x h px around the virtual camera's centre covers
  w x h px of the left view (+-1), centred d / 2 px right of the image centre (the left lens sits B / 2 left of
  the virtual one; +-0.5 px);
* the rectified-pair relation left[y, x] = right[y, x - d]: on an integer-disparity plane without noise the
  interior pixels agree within 2 DN, and a search over integer shifts finds d horizontally and ``vertical_px``
  vertically (-2..2);
* occlusion: a left pixel whose match x + 0.5 - d leaves the right image is occluded (exact, per column); a box at
  d_near in front of a background at d_far hides a strip of d_near - d_far px of background on its left (+-1 px);
* the documented camera model: gain g scales the tone-domain value s^(1/2.2) by g^(1/2.2) (mean ratio +-0.005, per
  pixel +-1 DN of rounding), gamma raises it to gamma (+-1.5 DN), vignetting v multiplies the light by
  1 - v r^2 (r = radius over the corner's; +-1.5 DN), read noise has its std in DN (+-10 %) and is independent
  between the cameras; JPEG keeps the mean (0.5 DN) but changes most pixels; a Gaussian blur is a low-pass filter
  (gradient energy below half), and the left camera is untouched by the right camera's impairments (exact);
* ``write_pair`` + ``real_pairs.load_pair``: gt.png holds round(64 d), so d comes back within 1/128 px (NaN kept);
  mask and images lossless (PNG), ``max_disparity`` kept; a folder holding files is refused untouched;
* determinism: the same seed gives the same images, another seed other noise.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from tpnet_gpu.bench.accuracy import real_pairs as rp
from tpnet_gpu.bench.accuracy.rendered_pairs import pair_rig
from tpnet_gpu.camera import Rig
from tpnet_gpu.scenes import textures as tx
from tpnet_gpu.scenes.image_pairs import GT_SCALE, ImagePair, Impairments, render_pair, write_pair
from tpnet_gpu.scenes.objects import Scene, Sky, plane

# image_pairs._left_truth subtracts the sky's infinite depths (inf - inf) before masking them out: harmless here

RIG = pair_rig(128, 96)
H, W = RIG.height, RIG.width
TEXTURE = tx.noise_texture(np.random.default_rng(0), 256, contrast=0.4)  # mean 0.4: unclipped at exposure 0.8
TONE = 1 / 2.2  # the documented tone curve: 8-bit value = 255 * signal^(gamma / 2.2)
NONE = Impairments()  # an ideal pair
MARGIN = 12  # interior: away from the reflecting borders of the optics' blur and from the shifted-out columns


def _d_of(distance_m: float) -> float:
    """geometry_and_lma.md E, written out: d = f B / (Z p), Z in mm."""
    return RIG.focal_mm * RIG.baseline_mm / (distance_m * 1000.0 * RIG.pixel_size_mm)


def _wall(d: float, **kw):
    """A fronto-parallel plane at disparity ``d`` (unbounded unless ``size_px``)."""
    return plane(RIG, float(RIG.distance(d)), TEXTURE, **kw)


def _render(scene: Scene, impair: Impairments = NONE, *, noise: bool = False, seed: int = 0) -> ImagePair:
    return render_pair(scene, RIG, impair, supersample=1, noise=noise, seed=seed)


def _shift_error(left, right, dx: int, dy: int) -> float:
    """Mean |left[y, x] - right[y + dy, x - dx]| over the interior, DN."""
    lft = left[MARGIN:H - MARGIN, MARGIN:W - MARGIN].astype(np.float64)
    rgt = right[MARGIN + dy:H - MARGIN + dy, MARGIN - dx:W - MARGIN - dx].astype(np.float64)
    return float(np.abs(lft - rgt).mean())


# --- ground truth ------------------------------------------------------------------------------------------------
def test_fronto_plane_has_f_b_over_z_p_where_it_covers_and_nan_on_the_sky():
    z = 70.0  # m: d = 7.54 px, not a round number
    d = _d_of(z)
    pair = _render(Scene([plane(RIG, z, TEXTURE, size_px=(60, 40))], Sky()))
    covered = np.isfinite(pair.disparity)
    np.testing.assert_allclose(pair.disparity[covered], d, rtol=1e-9)
    assert np.isnan(pair.disparity[~covered]).all() and not pair.nonocc[~covered].any()  # the sky
    ys, xs = np.nonzero(covered)
    assert abs(len(np.unique(xs)) - 60) <= 1 and abs(len(np.unique(ys)) - 40) <= 1
    assert covered.sum() == len(np.unique(xs)) * len(np.unique(ys))  # a rectangle
    # pixel centres: the left camera sees the virtual camera's point c at c + d / 2
    assert abs((xs.min() + xs.max() + 1) / 2 - (W / 2 + d / 2)) <= 0.5
    assert abs((ys.min() + ys.max() + 1) / 2 - H / 2) <= 0.5


def test_right_image_is_the_left_shifted_by_the_disparity():
    d = 6
    pair = _render(Scene([_wall(d)], Sky()))
    np.testing.assert_allclose(pair.disparity, d, rtol=1e-9)
    diff = pair.left[MARGIN:-MARGIN, MARGIN:-MARGIN].astype(int) - pair.right[MARGIN:-MARGIN, MARGIN - d:-MARGIN - d]
    assert np.abs(diff).max() <= 2, np.abs(diff).max()
    errors = [_shift_error(pair.left, pair.right, dx, 0) for dx in range(12)]
    assert int(np.argmin(errors)) == d and errors[d] < 0.5
    assert min(errors[d - 1], errors[d + 1]) > 3.0  # the texture tells the shifts apart


@pytest.mark.parametrize("vertical", [0.0, 1.0, -1.0])
def test_vertical_misalignment_moves_the_right_content_down(vertical):
    """``vertical_px`` = 1: right[y + 1, x - d] = left[y, x]; the best integer shift over -2..2 is the offset."""
    d = 6
    pair = _render(Scene([_wall(d)], Sky()), Impairments(vertical_px=vertical))
    errors = [_shift_error(pair.left, pair.right, d, dy) for dy in range(-2, 3)]
    assert int(np.argmin(errors)) - 2 == round(vertical) and min(errors) < 0.5, errors


# --- non-occlusion -----------------------------------------------------------------------------------------------
def test_left_pixels_whose_match_leaves_the_right_image_are_occluded():
    d = 6.3  # pixel centre x + 0.5 - d < 0 for x <= 5: columns 0..5 have no match in the right image
    pair = _render(Scene([_wall(d)], Sky()))
    assert not pair.nonocc[:, :6].any()
    assert pair.nonocc[:, 6:].all()


def test_near_box_hides_a_strip_of_the_background_on_its_left():
    """The box covers left columns [a, b) at d_near; the right camera sees the background at x - d_far and the box
    at [a - d_near, b - d_near): background left pixels x in [a - (d_near - d_far), a) are hidden behind it."""
    far, near = 4.0, 16.0
    pair = _render(Scene([_wall(far), _wall(near, size_px=(40, 40))], Sky()))
    box = np.isclose(pair.disparity, near)
    rows = np.nonzero(box.any(axis=1))[0]
    assert abs(len(rows) - 40) <= 1 and pair.nonocc[box].all()  # the box itself is seen by both cameras
    edge = int(np.ceil(far - 0.5))  # the image-edge strip of the background (previous test)
    for y in range(H):
        hidden = np.nonzero(~pair.nonocc[y, edge:])[0] + edge
        if y not in rows:
            assert hidden.size == 0, y
            continue
        first = np.nonzero(box[y])[0].min()
        assert abs(hidden.size - (near - far)) <= 1, (y, hidden)
        assert hidden.max() == first - 1 and np.all(np.diff(hidden) == 1), (y, hidden)  # one strip, at the box
        np.testing.assert_allclose(pair.disparity[y, hidden], far)  # background pixels


@pytest.mark.parametrize("vertical", [1.0, -1.0])
def test_rows_whose_match_leaves_the_right_image_vertically_are_occluded(vertical):
    """``vertical_px`` = 1: the last row's point is seen at y = H + 0.5 by the right camera, outside its image (and
    the first row's at y = -0.5 for -1), exactly as a match leaving it sideways."""
    pair = _render(Scene([_wall(6.0)], Sky()), Impairments(vertical_px=vertical))
    outside = -1 if vertical > 0 else 0
    assert not pair.nonocc[outside].any()


# --- the camera model ----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def ideal():
    """The reference pair: one plane at 6 px, no noise, no impairments (tone values well inside 5..250)."""
    pair = _render(Scene([_wall(6.0)], Sky()))
    assert 5 < pair.left.min() and pair.left.max() < 250 and 5 < pair.right.min() and pair.right.max() < 250
    return pair


def test_gain_darkens_the_right_image_through_the_tone_curve(ideal):
    gain = 0.5
    pair = _render(Scene([_wall(6.0)], Sky()), Impairments(gain=gain))
    np.testing.assert_array_equal(pair.left, ideal.left)  # the right camera's exposure only
    assert pair.right.mean() / ideal.right.mean() == pytest.approx(gain**TONE, abs=0.005)
    np.testing.assert_allclose(pair.right, ideal.right * gain**TONE, atol=1.0)  # both rounded to 1 DN


def test_gamma_raises_the_right_tone_values_to_it(ideal):
    pair = _render(Scene([_wall(6.0)], Sky()), Impairments(gamma=2.0))
    np.testing.assert_array_equal(pair.left, ideal.left)
    np.testing.assert_allclose(pair.right, 255.0 * (ideal.right / 255.0) ** 2, atol=1.5)


def test_vignetting_darkens_both_images_quadratically_in_the_radius(ideal):
    v = 0.5
    pair = _render(Scene([_wall(6.0)], Sky()), Impairments(vignetting=v))
    y, x = np.mgrid[0:H, 0:W] + 0.5
    r2 = ((x - W / 2) ** 2 + (y - H / 2) ** 2) / ((W / 2) ** 2 + (H / 2) ** 2)
    for image, reference in ((pair.left, ideal.left), (pair.right, ideal.right)):
        np.testing.assert_allclose(image, reference * (1.0 - v * r2) ** TONE, atol=1.5)


def test_jpeg_changes_pixels_but_keeps_the_mean(ideal):
    pair = _render(Scene([_wall(6.0)], Sky()), Impairments(jpeg_quality=30))
    for image, reference in ((pair.left, ideal.left), (pair.right, ideal.right)):
        assert np.mean(image != reference) > 0.5  # lossy: most pixels move
        assert abs(image.mean() - reference.mean()) < 0.5  # the DC terms are kept


def test_blur_lowers_the_right_gradient_energy(ideal):
    pair = _render(Scene([_wall(6.0)], Sky()), Impairments(blur_px=1.5))

    def energy(image):
        inner = image[MARGIN:-MARGIN, MARGIN:-MARGIN].astype(np.float64)
        return np.mean(np.diff(inner, axis=0) ** 2) + np.mean(np.diff(inner, axis=1) ** 2)

    np.testing.assert_array_equal(pair.left, ideal.left)  # the right camera's lens only
    assert energy(pair.right) < 0.5 * energy(ideal.right)
    assert abs(pair.right.mean() - ideal.right.mean()) < 1.0  # a normalised filter keeps the mean


def test_read_noise_has_its_std_and_each_seed_its_own_noise(ideal):
    scene = Scene([_wall(6.0)], Sky())
    impair = Impairments(read_noise=2.0)
    a = _render(scene, impair, noise=True, seed=1)
    b = _render(scene, impair, noise=True, seed=1)
    c = _render(scene, impair, noise=True, seed=2)
    np.testing.assert_array_equal(a.left, b.left)
    np.testing.assert_array_equal(a.right, b.right)
    assert np.mean(a.left != c.left) > 0.5 and np.mean(a.right != c.right) > 0.5
    noise_left = a.left - ideal.left.astype(np.float64)
    noise_right = a.right - ideal.right.astype(np.float64)
    expected = np.hypot(2.0, np.sqrt(1 / 12))  # Gaussian read noise plus rounding to 1 DN
    for noise in (noise_left, noise_right):
        assert noise.std() == pytest.approx(expected, rel=0.1) and abs(noise.mean()) < 0.1
    assert abs(np.corrcoef(noise_left.ravel(), noise_right.ravel())[0, 1]) < 0.1  # one sensor each
    quiet = _render(scene, impair, noise=False)
    np.testing.assert_array_equal(quiet.left, ideal.left)


# --- validation ------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("field, value", [("gain", 0.0), ("gain", np.nan), ("gamma", 11.0), ("vertical_px", 9.0),
                                          ("vertical_px", np.nan), ("vignetting", 1.0), ("vignetting", -0.1),
                                          ("jpeg_quality", 0), ("jpeg_quality", 101), ("read_noise", -1.0),
                                          ("blur_px", -0.5), ("full_well", -1.0)])
def test_impairments_reject_a_bad_field_naming_it(field, value):
    with pytest.raises(ValueError, match=rf"^{field}: expected"):
        Impairments(**{field: value})


def test_impairments_accept_their_limits():
    Impairments(gain=0.1, gamma=10.0, vertical_px=-4.0, vignetting=0.99, jpeg_quality=1, read_noise=0.0)
    Impairments(jpeg_quality=100, vertical_px=4.0)


def test_render_pair_refuses_a_rig_that_is_not_a_rectified_pair():
    with pytest.raises(ValueError, match="^rig: expected an ideal rectified pair"):
        render_pair(Scene(), Rig(width=64, height=48))  # the quad


# --- the realdata layout ----------------------------------------------------------------------------------------------
def test_write_pair_round_trips_through_load_pair(tmp_path):
    slanted = plane(RIG, 60.0, TEXTURE, size_px=(120, 90), tilt_deg=50.0, pan_deg=30.0)  # d 8.56..9.05 px, sky
    pair = _render(Scene([slanted], Sky()))
    known = np.isfinite(pair.disparity)
    assert 0.3 < known.mean() < 0.9 and np.ptp(pair.disparity[known]) > 0.3
    folder = write_pair(pair, tmp_path / "new" / "pair", max_disparity=40, source="a test")
    assert folder == tmp_path / "new" / "pair"
    back = rp.load_pair(folder)
    assert back.name == "pair" and back.max_disparity == 40.0
    np.testing.assert_array_equal(np.isfinite(back.gt), known)
    assert np.abs(back.gt[known] - pair.disparity[known]).max() <= 0.5 / GT_SCALE + 1e-12  # 1/128 px
    assert GT_SCALE == 64  # the realdata layout's 1/64 px steps
    np.testing.assert_array_equal(back.mask, pair.nonocc)
    for path, image in ((back.left, pair.left), (back.right, pair.right)):
        with Image.open(path) as im:
            np.testing.assert_array_equal(np.asarray(im), image)
    assert json.loads((folder / "meta.json").read_text())["source"] == "a test"


def test_write_pair_refuses_a_folder_holding_files(tmp_path):
    pair = _render(Scene([_wall(6.0)], Sky()))
    (tmp_path / "keep.txt").write_text("precious")
    with pytest.raises(FileExistsError, match="^folder: expected a new or empty folder"):
        write_pair(pair, tmp_path, max_disparity=16)
    assert [p.name for p in tmp_path.iterdir()] == ["keep.txt"]
    assert (tmp_path / "keep.txt").read_text() == "precious"
    (tmp_path / "empty").mkdir()
    assert (write_pair(pair, tmp_path / "empty", max_disparity=16) / "gt.png").is_file()  # empty is fine


def test_write_pair_refuses_a_disparity_beyond_16_bits(tmp_path):
    """gt.png holds round(64 d) in 16 bits: d >= 65535 / 64 = 1024 px cannot be stored."""
    grey = np.zeros((16, 16), dtype=np.uint8)
    far = ImagePair(grey, grey, np.full((16, 16), 1100.0), np.ones((16, 16), dtype=bool))
    with pytest.raises(ValueError, match="^pair: a disparity over 1024 px"):
        write_pair(far, tmp_path / "far", max_disparity=2000)
    assert not (tmp_path / "far").exists()


def test_finish_raws_follows_the_tone_curve():
    """Oracle: 255 (gain x)^(gamma / 2.2), rounded, of a linear ramp x (black 64, white 4095), per camera; a blur
    lowers the gradient energy and keeps the linear mean (1 %); JPEG moves pixels but not the mean (1 DN)."""
    from tpnet_gpu.scenes.image_pairs import PhotoFinish, finish_raws

    x = np.linspace(0.0, 1.0, 64 * 48).reshape(48, 64)
    raws = np.stack([np.round(64 + x * (4095 - 64))] * 2).astype(np.uint16)
    linear = (raws[0].astype(np.float64) - 64) / (4095 - 64)
    out = finish_raws(raws, 64, 4095, [PhotoFinish(), PhotoFinish(gain=1.5, gamma=1.2)])
    assert out.dtype == np.uint16 and out.max() <= 255
    np.testing.assert_array_equal(out[0], np.round(255 * linear ** (1 / 2.2)))
    np.testing.assert_array_equal(out[1], np.round(255 * np.clip(1.5 * linear, 0, 1) ** (1.2 / 2.2)))
    rng = np.random.default_rng(0)
    texture = np.round(64 + rng.uniform(0.2, 0.6, (2, 48, 64)) * 4000).astype(np.uint16)
    plain, blurred, jpeg = (finish_raws(texture, 64, 4095, [f, f]).astype(np.float64)
                            for f in (PhotoFinish(), PhotoFinish(blur_px=1.0), PhotoFinish(jpeg_quality=75)))
    energy = lambda a: (np.diff(a, axis=-1) ** 2).mean()  # noqa: E731
    linear_mean = lambda a: ((a / 255) ** 2.2).mean()  # noqa: E731 - the blur acts on the linear signal
    assert energy(blurred) < 0.5 * energy(plain) and linear_mean(blurred) == pytest.approx(linear_mean(plain), rel=0.01)
    assert (jpeg != plain).mean() > 0.5 and abs(jpeg.mean() - plain.mean()) < 1.0
    draws = [PhotoFinish.draw(np.random.default_rng(s)) for s in range(200)]
    assert all(0.7 <= d.gain <= 1.3 and 0.85 <= d.gamma <= 1.15 and 0 <= d.blur_px <= 0.8 for d in draws)
    assert 0.3 < np.mean([d.blur_px > 0 for d in draws]) < 0.7
    assert 0.5 < np.mean([d.jpeg_quality is not None for d in draws]) < 0.8


def test_photo_optics_stay_in_their_ranges():
    """Oracle: the documented ranges (sigma 0.15-0.6 px on axis, corner up to 0.3 px more, lateral colour 0-0.6)."""
    from tpnet_gpu.scenes.image_pairs import photo_optics

    lenses = [photo_optics(np.random.default_rng(s)) for s in range(100)]
    assert all(0.15 <= o.sigma_centre <= 0.6 and 0 <= o.sigma_edge - o.sigma_centre <= 0.3 and 0 <= o.lateral_ca <= 0.6
               for o in lenses)
    assert np.ptp([o.sigma_centre for o in lenses]) > 0.3  # they vary
