"""The disparity search's memory, told before it is allocated: its one range-sized part is the engine's two cost
volumes (``volume.CostVolume``: every tile, and the sparse grid; values, cost and aggregation, float32), so a
frame and range are checked against the run's budget (``runtime.memory``) before an engine exists.
"""

from __future__ import annotations

from tpnet_gpu.config import EngineConfig
from tpnet_gpu.layout import TILE_STRIDE
from tpnet_gpu.runtime import memory

SPARSE = 2  # the first stage's sparse grid takes every SPARSE-th tile in each direction (engine.SPARSE)


def search_bytes(height: int, width: int, d_min: float, d_max: float, config: EngineConfig) -> float:
    """Bytes of one engine's range-sized buffers for a ``height`` x ``width`` frame searched over
    ``[d_min, d_max]`` (bins of ``config.bin_step`` over the range widened by ``config.reach`` each side)."""
    tiles_y, tiles_x = height // TILE_STRIDE, width // TILE_STRIDE
    sparse = ((tiles_y + SPARSE - 1) // SPARSE) * ((tiles_x + SPARSE - 1) // SPARSE)
    bins = round((d_max - d_min + 2 * config.reach) / config.bin_step) + 1
    return 3 * 4.0 * bins * (tiles_y * tiles_x + sparse)


def check(height: int, width: int, d_min: float, d_max: float, config: EngineConfig, device: str,
          engines: int = 1, frame_bytes: float = 0.0) -> None:
    """A ``ValueError`` naming ``memory_limit_gb`` when ``engines`` engines of this frame and range (and
    ``frame_bytes`` of the caller's own) need more than ``config.memory_limit_gb`` (``runtime.memory.check``)."""
    need = engines * search_bytes(height, width, d_min, d_max, config) + frame_bytes
    what = (f"searching {d_min:g}..{d_max:g} px (min_disparity..max_disparity) over the {width}x{height} frame"
            + (f" ({engines} engines: the cross-check's too)" if engines > 1 else "")
            + (" with the frame's own buffers" if frame_bytes else ""))
    memory.check(need, config.memory_limit_gb, device, what)
