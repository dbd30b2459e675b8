"""Parameters of the tile processor (tile_processor.md §6.5, §9). Frozen dataclasses; units in comments."""

from __future__ import annotations

from dataclasses import dataclass

from tpnet_gpu import tables


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
        if self.fat_zero < 0 or self.sigma_rb <= 0 or sigma <= 0:
            raise ValueError(
                f"fat_zero >= 0 and sigmas > 0 expected, got fat_zero={self.fat_zero}, "
                f"sigma_rb={self.sigma_rb}, sigma_corr={sigma}"
            )
        return CorrelationConfig(tuple(float(w) for w in weights), float(self.fat_zero), float(self.sigma_rb),
                                 float(sigma), float(self.net_offset))


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
        if self.diff_sigma <= 0 or self.min_shot <= 0 or min(sigmas) <= 0:
            raise ValueError(
                f"diff_sigma, min_shot and lpf_sigmas must be > 0, got {self.diff_sigma}, {self.min_shot}, {sigmas}"
            )
        return TextureConfig(tuple(map(float, sigmas)), tuple(map(float, weights)), float(self.diff_sigma),
                             float(self.min_shot), float(self.scale_shot), bool(self.dust_remove),
                             float(self.output_gain))
