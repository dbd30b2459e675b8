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
