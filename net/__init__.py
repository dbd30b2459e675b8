"""TPNET in PyTorch (installed as ``tpnet_gpu.net``)."""
