"""tpnet-gpu: quad-camera Tile Processor (MCLT phase correlation) and the TPNET disparity network.

Re-creates the GPU Tile Processor and TPNET of Filippov and Dzhimiev, "See far with TPNET: a Tile Processor
and a CNN Symbiosis" (Elphel), on NVIDIA Warp and PyTorch.
"""

__version__ = "0.1.0"
