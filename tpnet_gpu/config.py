"""Every default of the project in one place: the tile processor's parameters (tile_processor.md §6.5, §9), the
baseline's correlation, the data set and the training settings. Frozen dataclasses; units in comments."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tpnet_gpu import tables

BACKENDS = ("warp", "taichi")  # the tile processor's kernel languages
# A frame of at most this many pixels is start-up bound (docs/platform.md §4): the Warp backend starts ~1 CPU-second
# sooner than Taichi and runs such a frame as fast, so it is the default there (TileProcessor).
SMALL_FRAME_PIXELS = 320 * 240
# `tpnet process` on one frame of at most this many pixels runs on Warp: the process ends after that frame, and
# Taichi's front end and kernel loading (~2 s) outweigh its faster frame up to about here (docs/platform.md §4:
# a 640x480 pair one-shot 4.6 s on Warp against 6.2 s on Taichi; 1280x960 11.1 against 9.4 s)
ONE_SHOT_PIXELS = 640 * 480
METHODS = ("auto", "tpnet", "engine")  # what makes the disparity: PipelineConfig.method, `tpnet process --method`
MEASURES = ("lma", "axis")  # the disparity engine's per-tile measurements
NEAR_DRAWS = 2  # "near" training targets per scene (ground truth + a small log-uniform offset)


def _integers(settings, **lows: int) -> None:
    """A ``ValueError`` naming the first of ``settings``' fields ``lows`` that is not an int (bool excluded) in
    [low, 2**63)."""
    for name, low in lows.items():
        value = getattr(settings, name)
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value < 2**63:
            raise ValueError(f"{name}: expected an integer >= {low}, got {value!r}")


def _finite(name: str, value, *, positive: bool) -> float:
    """``value`` as a float, or a ``ValueError`` naming ``name``: finite and > 0 (``positive``) or >= 0. Written
    as ``not (x > 0)``, not ``x <= 0``: NaN fails every comparison (issue 16: NaN settings were accepted)."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = float("nan")
    if isinstance(value, bool) or not (np.isfinite(number) and (number > 0 if positive else number >= 0)):
        raise ValueError(f"{name}: expected a finite number {'> 0' if positive else '>= 0'}, got {value!r}")
    return number


def _weights(name: str, values) -> tuple[float, ...]:
    """Colour weights: finite, >= 0, at least one > 0."""
    out = tuple(_finite(name, v, positive=False) for v in values)
    if not any(out):
        raise ValueError(f"{name}: expected at least one weight > 0, got {values!r}")
    return out


def target_variants(near_draws: int = NEAR_DRAWS) -> tuple[str, ...]:
    """Names of the training-target variants: the baseline's, a random +-2 px offset, and the near draws."""
    return ("heuristic", "random") + tuple(f"near{i}" for i in range(near_draws))


@dataclass(frozen=True)
class CorrelationConfig:
    """Phase-correlation parameters of the GPU path.

    ``None`` picks the spec default for the processor's colour count: weights (R, B, G) = (0.25, 0.25, 0.5)
    or (1,) for mono; final low-pass sigma 0.9 or 0.15 for mono. Sigmas are used as variances, as in the
    original (tables.lpf).
    """

    colour_weights: tuple[float, ...] | None = None
    fat_zero: float = tables.CORR_FAT_ZERO  # absolute, in units of the colour-weighted product
    sigma_rb: float = tables.CORR_SIGMA_RB  # low-pass after R + B (colour only)
    sigma_corr: float | None = None  # low-pass after normalisation
    net_offset: float = tables.NET_CORR_OFFSET  # pair combination of the network layers; < 0: plain mean

    def resolved(self, colours: int) -> CorrelationConfig:
        """A copy with the ``None`` defaults filled in for ``colours`` (1 or 3); checks the weights' count."""
        weights = self.colour_weights
        if weights is None:
            weights = tables.CORR_COLOUR_WEIGHTS if colours == 3 else (1.0,)
        if len(weights) != colours:
            raise ValueError(f"colour_weights: expected {colours} values, got {len(weights)}")
        sigma = self.sigma_corr
        if sigma is None:
            sigma = tables.CORR_SIGMA if colours == 3 else tables.CORR_SIGMA_MONO
        if not np.isfinite(float(self.net_offset)):
            raise ValueError(f"net_offset: expected a finite number (< 0: the plain mean), got {self.net_offset!r}")
        return CorrelationConfig(_weights("colour_weights", weights), _finite("fat_zero", self.fat_zero, positive=False),
                                 _finite("sigma_rb", self.sigma_rb, positive=True),
                                 _finite("sigma_corr", sigma, positive=True), float(self.net_offset))


@dataclass(frozen=True)
class TextureConfig:
    """Texture parameters (tile_processor.md §7.3). ``None`` picks the spec default for the colour count:
    low-pass sigmas (R, B, G) = (0.9, 0.9, 0.6) or (0.4,) for mono; comparison weights (0.294, 0.118, 0.588)
    or (1,). ``diff_sigma`` and ``min_shot`` are in the processor's units (~1/4 of raw values), as in the
    original, which presumed its sensors' range: scale them with the data."""

    lpf_sigmas: tuple[float, ...] | None = None
    colour_weights: tuple[float, ...] | None = None
    diff_sigma: float = tables.TEXTURE_DIFF_SIGMA
    min_shot: float = tables.TEXTURE_MIN_SHOT
    scale_shot: float = tables.TEXTURE_SCALE_SHOT
    dust_remove: bool = True
    output_gain: float = tables.TEXTURE_OUTPUT_GAIN

    def resolved(self, colours: int) -> TextureConfig:
        """A copy with the ``None`` defaults filled in for ``colours`` (1 or 3); checks counts and signs."""
        sigmas = self.lpf_sigmas
        if sigmas is None:
            sigmas = tables.TEXTURE_SIGMAS if colours == 3 else (tables.TEXTURE_SIGMA_MONO,)
        weights = self.colour_weights
        if weights is None:
            weights = tables.TEXTURE_COLOUR_WEIGHTS if colours == 3 else (1.0,)
        if len(sigmas) != colours or len(weights) != colours:
            raise ValueError(
                f"lpf_sigmas, colour_weights: expected {colours} values each, got {len(sigmas)} and {len(weights)}"
            )
        positive = {name: _finite(name, getattr(self, name), positive=True)
                    for name in ("diff_sigma", "min_shot", "scale_shot", "output_gain")}
        return TextureConfig(lpf_sigmas=tuple(_finite("lpf_sigmas", v, positive=True) for v in sigmas),
                             colour_weights=_weights("colour_weights", weights), dust_remove=bool(self.dust_remove),
                             **positive)


# The correlation the baseline measures with (our recommended choice, by measurement): green only. The as-coded
# mix (R 0.25, B 0.25, G 0.5) skews the phase-correlation peak of Bayer data at fractional per-camera shifts:
# the zero-filled quarter-density R and B lattices alias, and phase normalisation amplifies their aliased
# bins. On a rendered plane at 3.3 px the LMA read a residual of +0.18-0.20 px at the true disparity with
# the as-coded mix and 0.009 with green only; plain correlation (huge fat zero) is unskewed but loses the
# phase-correlation strength scale the LMA thresholds are set for. The fat zero (absolute, units of the
# product of two CLT tiles) suits 12-bit raw data near mid-scale: it keeps noise-only frequencies (sky,
# flat colours) from forming confident peaks (bench_accuracy: low-texture tiles measured 96 % -> 10 %).
BASELINE_CORRELATION = CorrelationConfig(colour_weights=(0.0, 0.0, 1.0), fat_zero=1.0e4)


@dataclass(frozen=True)
class DatasetSpec:
    """What to build: ``scenes`` random scenes of ``width`` x ``height`` (seeded by ``seed`` + index),
    ``test_fraction`` of them held out (by scene), targets offset by up to ``random_offset`` px."""

    scenes: int = 40
    width: int = 640
    height: int = 480
    test_fraction: float = 0.2
    seed: int = 0
    random_offset: float = 2.0
    supersample: int = 2
    # the layers' correlation settings, as the baseline's (BASELINE_CORRELATION): green only, fat zero 1e4
    fat_zero: float = BASELINE_CORRELATION.fat_zero
    colour_weights: tuple = BASELINE_CORRELATION.colour_weights
    near_offset: tuple = (0.005, 0.5)
    near_draws: int = NEAR_DRAWS
    # the rig the scenes are rendered with: a rig file's fields (docs/rig_file.md, ``rigfile.rig_to_dict``);
    # None: the quad (``Rig()``). An ideal rig takes the spec's size; a calibrated one must have it.
    rig: dict | None = None
    # the cameras' Bayer pattern, or None: mono frames (grey images; ``colour_weights`` then has one value)
    cfa: str | None = tables.DEFAULT_CFA
    # mono frames made like ordinary photographs: a random lens per scene (scenes.image_pairs.photo_optics), and
    # per camera a random gain, tone curve, blur and JPEG, 8 bits gamma-encoded (finish_raws) - what
    # `tpnet process LEFT.png RIGHT.png` reads
    photo: bool = False
    # the probability that each random object is curved (a sphere or an upright cylinder, scenes.curved) instead
    # of a plane: disparity that bends inside a tile and turns steep at outlines, as photographed objects do
    curved: float = 0.0

    def __post_init__(self):
        _integers(self, scenes=1, width=16, height=16, seed=0, supersample=1, near_draws=0)  # numpy's
        # generators and the renderer take no other
        if not 0.0 <= self.curved <= 1.0:
            raise ValueError(f"curved: expected a probability in [0, 1], got {self.curved!r}")
        if not 0.0 <= self.test_fraction < 1.0:
            raise ValueError(f"test_fraction: expected a share in [0, 1), got {self.test_fraction!r}")
        colours = 1 if self.cfa is None else 3
        if len(self.colour_weights) != colours:
            raise ValueError(f"colour_weights: expected {colours} value(s) for cfa {self.cfa!r}, got "
                             f"{tuple(self.colour_weights)} (mono frames: colour_weights=(1.0,))")
        if self.photo and self.cfa is not None:
            raise ValueError(f"photo: finishes mono frames as photographs; expected cfa None, got {self.cfa!r}")

    def variants(self) -> tuple:
        """Names of the target variants each chunk holds."""
        return target_variants(self.near_draws)

    def correlation(self) -> CorrelationConfig:
        """The tile processor's correlation settings for the network layers."""
        return CorrelationConfig(colour_weights=tuple(self.colour_weights), fat_zero=self.fat_zero)

    def split(self) -> list[str]:
        """'train' / 'test' per scene index, a seeded permutation (at least one test scene when >= 2)."""
        n_test = int(round(self.scenes * self.test_fraction)) if self.scenes > 1 else 0
        n_test = max(n_test, 1) if self.scenes > 1 and self.test_fraction > 0 else n_test
        order = np.random.default_rng(self.seed).permutation(self.scenes)
        labels = ["train"] * self.scenes
        for i in order[:n_test]:
            labels[int(i)] = "test"
        return labels


@dataclass(frozen=True)
class TrainConfig:
    """Training settings. ``epochs`` passes over the training samples (scenes x variants), ``batch`` samples
    per step; LR schedule (network.md §7) scaled to ``epochs``; ``w_mode`` of the Laplacian regulariser."""

    epochs: int = 60
    batch: int = 4
    seed: int = 0
    max_offset: float = 2.0
    mirror_lambda: float = 0.1
    weights_lambda: float = 0.5
    w_mode: str = "as_coded"
    hard_share: float = 0.5
    variants: tuple = target_variants()
    # per-variant loss weights (network.md §5.1 BATCH_WEIGHTS, meant but never applied in the original):
    # random-offset targets teach large corrections; heuristic and near ones the precision near the answer
    variant_weights: tuple = (1.0, 1.0, 1.0, 1.0)
    # errors scaled by c / (|target - gt| + c), c = error_scale px (None: plain errors, as the original): the
    # loss asks for an error proportional to the target's, so both coarse corrections and the precision near
    # the answer count, and repeated passes converge
    error_scale: float | None = 0.3
    # fine-tuning: the weights the run starts from (None: fresh Xavier weights) and the fraction of the LR
    # schedule it starts at (0.3: from 3e-5, below the rate that would undo what the weights learnt)
    init: str | None = None
    lr_from: float = 0.0
    # the network's own pass (network.md §6): every ``pass_every`` epochs each training scene gets a "pass" sample,
    # the model's prediction from its heuristic targets with the layers re-measured there from the scene's raw
    # frames, so a second pass learns to converge instead of drifting (None: no such samples)
    pass_every: int | None = None

    def __post_init__(self):
        _integers(self, epochs=1, batch=1, seed=0)  # what torch and numpy take
        if self.pass_every is not None and (isinstance(self.pass_every, bool) or not isinstance(self.pass_every, int)
                                            or self.pass_every < 1):
            raise ValueError(f"pass_every: expected None or a positive number of epochs, got {self.pass_every!r}")
        if not 0.0 <= self.lr_from < 1.0:
            raise ValueError(f"lr_from: expected a schedule fraction in [0, 1), got {self.lr_from!r}")
        if len(self.variant_weights) != len(self.variants):
            raise ValueError(f"variant_weights: expected one weight per variant {self.variants}, "
                             f"got {self.variant_weights}")


@dataclass(frozen=True)
class EngineConfig:
    """The disparity engine (tpnet_gpu/disparity, docs/disparity.md): a sparse full-range search, one pass of
    every tile at its answer, a full-range sweep of the doubtful tiles, then sparse refinement.

    Disparities in px. The range searched is the engine's (``DisparityEngine`` / ``Pipeline``'s
    ``min_disparity``, ``max_disparity``: one door); without a maximum it ends at the rig's disparity at
    ``nearest_m`` metres.
    Each pass's correlations are read within +-``reach`` px of its target; sweeps step 2 ``reach`` - 2 px.
    A tile is doubtful when its aggregated-cost margin is < ``verify_margin`` with a correlation >=
    ``verify_strength`` at its choice. Aggregation (SGM over the tile grid) penalties ``p1`` (one-bin step),
    ``p2`` (any jump), on costs 1 - correlation, bins of ``bin_step`` px. Refinement: at most ``refine_passes``
    re-correlations of the tiles that still move more than ``tolerance`` px; a measurement counts where its
    strength >= ``min_strength`` and |residual| <= ``trust``. ``measure``: "axis" (the pairs' combined peak, any
    rig, all on the device) or "lma" (the quad's LMA peak fit, float64 on the host); the same flat-tile precision
    on rendered tuning scenes. A rig whose pairs lie along quad pairs (a binocular rig: the quad's pair 0) takes
    "lma" with the other quad pairs masked off (``disparity.measure.lma_slots``); other rigs always use "axis". A
    refined tile that ends more than ``leash`` px from a first-stage answer whose margin is >= ``leash_margin``
    keeps the first stage's answer. ``memory_limit_gb``: the budget of the engine's range-sized buffers (its cost
    volumes, ``disparity.budget``), GB; None: ``runtime.memory.DEFAULT_SHARE`` of the memory
    available when it is made. A range and frame that need more are refused before anything is allocated."""

    nearest_m: float = 8.0
    reach: float = 6.0
    bin_step: float = 0.5
    p1: float = 0.08
    p2: float = 0.35
    refine_passes: int = 4
    tolerance: float = 0.03
    min_strength: float = 0.1
    trust: float = 4.0
    measure: str = "axis"
    verify_margin: float = 1.0
    verify_strength: float = 0.1
    leash: float = 1.0
    leash_margin: float = 0.5
    memory_limit_gb: float | None = None

    def __post_init__(self):
        limit = self.memory_limit_gb
        if limit is not None and (isinstance(limit, bool) or not isinstance(limit, (int, float))
                                  or not np.isfinite(limit) or limit <= 0):
            raise ValueError(f"memory_limit_gb: expected a finite number of GB > 0 or None, got {limit!r}")
        if self.measure not in MEASURES:
            raise ValueError(f"EngineConfig.measure: expected one of {MEASURES}, got {self.measure!r}")
        for name in ("reach", "bin_step", "nearest_m", "tolerance", "trust", "leash"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise ValueError(f"EngineConfig.{name}: expected a finite number > 0, got {value!r}")
        for name in ("p1", "p2", "min_strength", "verify_margin", "verify_strength", "leash_margin"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value >= 0):
                raise ValueError(f"EngineConfig.{name}: expected a finite number >= 0, got {value!r}")
        if not isinstance(self.refine_passes, int) or self.refine_passes < 0:
            raise ValueError(f"EngineConfig.refine_passes: expected an int >= 0, got {self.refine_passes!r}")


@dataclass(frozen=True)
class PipelineConfig:
    """``engine``: the disparity engine's settings; ``network_passes``: TPNET passes (when the pipeline has
    weights for its rig), each re-correlating at the previous one's disparity; ``textures``: make the RGBA
    texture; ``two_surface``: also fit both surfaces of tiles whose correlation shows two
    (``FrameResult.surfaces``, tpnet_gpu/disparity/two_surface.py); ``method`` (``tpnet process --method``):
    "auto" runs TPNET where weights shipped for default use fit the rig and frames, else the engine alone
    (logged); "tpnet" also takes the weights shipped on request (their recipe's ``on_request`` says why they
    are not the default; ValueError where none fit); "engine" runs the engine alone (to see what TPNET adds).

    Which answers come out (disparity.md §8): ``cross_check`` - the engine runs again with another camera as the
    reference and a tile whose answers disagree by more than ``checks.CROSS_CHECK_PX``, or whose windows leave
    an image at its answer, has no value (None: on for a two-camera rig, the stereo left-right check; it costs
    a second engine run); then tiles of confidence below ``min_confidence`` and all but the ``keep_fraction``
    most confident answers have none. ``per_pixel``: also a per-pixel disparity (``FrameResult.pixels``) from
    the tile answers (``disparity/per_pixel.py``; mono frames with a camera at the reference; None: on where
    that holds and the rig has two cameras). With both (mono pairs by default) the check is made per pixel
    instead (disparity.md §10, ``disparity/pixel_check.py``): each view's per-pixel map, a left-right check,
    the rejected pixels filled with the background, and each tile's answer the window's mean of those pixels,
    its confidence the share of the window that backs it (no value below ``pixel_check.MIN_SUPPORT``, nor
    where the windows leave an image at the answer)."""

    engine: EngineConfig = EngineConfig()
    network_passes: int = 1
    textures: bool = True
    two_surface: bool = False
    cross_check: bool | None = None
    min_confidence: float = 0.0
    keep_fraction: float = 1.0
    per_pixel: bool | None = None
    method: str = "auto"

    def __post_init__(self):
        if not isinstance(self.network_passes, int) or self.network_passes < 1:
            raise ValueError(f"network_passes: expected an int >= 1, got {self.network_passes!r}")
        if self.method not in METHODS:
            raise ValueError(f"method: expected one of {', '.join(METHODS)}, got {self.method!r}")
        for name in ("cross_check", "per_pixel"):
            if not (getattr(self, name) is None or isinstance(getattr(self, name), bool)):
                raise ValueError(f"{name}: expected True, False or None (automatic), got {getattr(self, name)!r}")
        if not (isinstance(self.min_confidence, (int, float)) and 0.0 <= self.min_confidence < float("inf")):
            raise ValueError(f"min_confidence: expected a finite number >= 0, got {self.min_confidence!r}")
        if not (isinstance(self.keep_fraction, (int, float)) and 0.0 < self.keep_fraction <= 1.0):
            raise ValueError(f"keep_fraction: expected a number in (0, 1], got {self.keep_fraction!r}")


def disparity_range(min_disparity, max_disparity, rig, nearest_m: float) -> tuple[float, float]:
    """The range the disparity engine searches, px - its one home and default (``DisparityEngine``,
    ``Pipeline``, ``make_pipeline`` take ``min_disparity`` / ``max_disparity``): ``(min_disparity,
    max_disparity)`` checked (finite, max > min); None takes the default: 0 for the minimum, ``rig``'s
    (a ``camera.Rig``) disparity at ``nearest_m`` metres (``EngineConfig.nearest_m``) for the maximum, at most
    the frame's bound. The bound: a disparity d moves two cameras' tile windows apart by d times their offsets'
    difference, so |d| beyond the frame's side over the cameras' largest spread (per axis) leaves no tile with
    both windows on the frame - a range past it is refused naming the bound, before any work is sized by it (the
    same bound from whichever camera the rig is referenced to)."""
    min_disparity = 0.0 if min_disparity is None else min_disparity
    offsets = np.asarray(rig.offsets_array(), dtype=np.float64)
    spread = offsets.max(axis=0) - offsets.min(axis=0)  # (2,): x, y
    reach = min((side / span for side, span in ((rig.width, spread[0]), (rig.height, spread[1])) if span > 0),
                default=float("inf"))
    values = {"min_disparity": min_disparity, "max_disparity": max_disparity}
    for name, value in values.items():
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
                or not np.isfinite(value):
            raise ValueError(f"{name}: expected a finite number of pixels, got {value!r}")
        if abs(value) > reach:
            raise ValueError(f"{name}: expected at most {reach:g} px in magnitude (beyond it a camera's tile windows "
                             f"leave the {rig.width}x{rig.height} frame), got {value:g}")
    low = float(min_disparity)
    high = min(float(rig.disparity(nearest_m)), reach) if max_disparity is None else float(max_disparity)
    if high <= low:
        raise ValueError(f"max_disparity: expected more than min_disparity={low:g}, got {high:g}"
                         + (f" (the rig's disparity at {nearest_m:g} m)" if max_disparity is None else ""))
    return low, high
