"""Warp kernels of the tile processor (installed as ``tpnet_gpu.kernels``)."""
