"""The backend protocol of the tile processor: one kernel language's launches over ``Buffers``.

A backend runs named steps in order (``STEPS``); the processor decides which steps a call needs. Each backend
serialises its launches (Warp's CPU tile kernels share one scratch arena and abort when launched concurrently,
platform.md §1; Taichi has one runtime per process) and orders them with torch's current CUDA stream, so torch's
input copies and the readers of the outputs see the kernels' work in order.
"""

from __future__ import annotations

from typing import Protocol

import torch

# pad: frames -> padded frames; centres: target disparities -> ideal-rig tile centres; convert: padded frames and
# centres -> CLT tiles, finite and valid masks; correlate: CLT -> pair correlations (+ network layers);
# texture: CLT -> RGBA canvas; fused: padded frames and centres -> pair correlations (+ layers), finite and valid
# masks in one pass without the CLT buffer.
STEPS = ("pad", "centres", "convert", "correlate", "texture", "fused")


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
