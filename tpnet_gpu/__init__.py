"""tpnet-gpu: multi-camera Tile Processor (MCLT phase correlation) and the TPNET disparity network.

Re-creates the GPU Tile Processor and TPNET of Filippov and Dzhimiev, "See far with TPNET: a Tile Processor
and a CNN Symbiosis" (Elphel), on NVIDIA Warp, Taichi and PyTorch. The public API is ``__all__``; the names are
imported on first use (``import tpnet_gpu`` stays light: the CLI and the kernel-free modules do not pay for Warp
or torch until they use them).
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

# public name -> module that defines it
_EXPORTS = {
    "TileProcessor": "tpnet_gpu.processor",
    "TileResult": "tpnet_gpu.processor",
    "CorrelationConfig": "tpnet_gpu.config",
    "TextureConfig": "tpnet_gpu.config",
    "Pipeline": "tpnet_gpu.pipeline",
    "PipelineConfig": "tpnet_gpu.config",
    "FrameResult": "tpnet_gpu.pipeline",
    "load_frames": "tpnet_gpu.pipeline",
    "Rig": "tpnet_gpu.camera",
    "BaselineParams": "tpnet_gpu.baseline.estimate",
}

__all__ = sorted(_EXPORTS) + ["__version__"]


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module 'tpnet_gpu' has no attribute {name!r}")
    value = getattr(importlib.import_module(_EXPORTS[name]), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
