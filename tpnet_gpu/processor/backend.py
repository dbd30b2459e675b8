"""The backend protocol of the tile processor: one kernel language's launches over ``Buffers``.

A backend runs named steps in order (``STEPS``); the processor decides which steps a call needs. Each backend
serialises its launches (Warp's CPU tile kernels share one scratch arena and abort when launched concurrently,
platform.md §1; Taichi has one runtime per process) and orders them with torch's current CUDA stream, so torch's
input copies and the readers of the outputs see the kernels' work in order.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Protocol

import torch

# pad: frames -> padded frames; centres: target disparities -> ideal-rig tile centres; convert: padded frames and
# centres -> CLT tiles, finite and valid masks; correlate: CLT -> pair correlations (+ network layers);
# texture: CLT -> RGBA canvas; fused: padded frames and centres -> pair correlations (+ layers), finite and valid
# masks in one pass without the CLT buffer; convert_texture: the texture, each band's CLT tiles converted into the
# band buffer first (a processor without the whole-frame CLT buffer).
STEPS = ("pad", "centres", "convert", "correlate", "texture", "fused", "convert_texture")


def run_bands(bands: Sequence, read_tiles: Callable, write_pixels: Callable, convert_band: Callable | None) -> None:
    """The texture's band order, the same in every backend: per band of tile rows, ``read_tiles(band)`` (IMCLT:
    the last read of the band's CLT tiles), then ``write_pixels(band)`` (combine and overlap-add). With
    ``convert_band``, the first band is converted before it all and each next band between the two, because the
    combine's alpha fade reads the next band's ``finite`` flags and its CLT tiles may replace this band's only
    once they are read."""
    if convert_band is not None:
        convert_band(bands[0])
    for i, band in enumerate(bands):
        read_tiles(band)
        if convert_band is not None and i + 1 < len(bands):
            convert_band(bands[i + 1])
        write_pixels(band)


class Backend(Protocol):
    """What ``TileProcessor`` needs of a kernel language."""

    name: str

    def run(self, steps: tuple[str, ...], *, frames: torch.Tensor | None, masked: bool) -> None:
        """Launch ``steps`` (a sub-sequence of ``STEPS``) in order.

        Args:
            steps: the steps to run.
            frames: for ``pad``: ``(cams, H, W)`` float32 contiguous frames on the device to read in place, or
                None for the processor's staging buffer.
            masked: for ``convert`` and ``fused``: read the ``active`` mask buffer (else every tile is active).
        """
