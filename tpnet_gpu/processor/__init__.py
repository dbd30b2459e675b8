"""The tile processor (tile_processor.md): ``TileProcessor`` and its per-call ``TileResult``.

Modules: ``validate`` (pure input checks), ``buffers`` (every device array and its torch view), ``backend`` (the
protocol a kernel language implements), ``warp_backend`` and ``taichi_backend`` (its two implementations; graph
capture lives in the Warp one), ``tile_processor`` (the public class).
"""

from tpnet_gpu.processor.buffers import TileResult
from tpnet_gpu.processor.tile_processor import TileProcessor
from tpnet_gpu.processor.validate import BACKENDS

__all__ = ["BACKENDS", "TileProcessor", "TileResult"]
